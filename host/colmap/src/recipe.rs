//! The COLMAP recipes of `docs/mesh.md`, read from the doc itself: the tests that run COLMAP
//! (`tests::colmap_pipeline_both_ways`, `tests/tests/cli_fit_import.rs`) run the recipe a user
//! copies, word for word, so the doc cannot drift from what CI runs.
//!
//! Contract: [`recipe`] takes the first shell block after a heading and returns its steps up
//! to the first elided one (a line with `...` or `…`: the dense steps that need a GPU):
//! `export K=V` ([`Step::Env`]), `mkdir -p DIR…` ([`Step::Mkdir`]) and `colmap …`
//! ([`Step::Colmap`]); `ellipso` lines and comments are the caller's. A trailing `# comment`
//! is dropped and `\` continuations are joined. The doc's placeholders are words: `C` (the
//! export folder) and `R` (COLMAP's results, beside the export: a later `ellipso export` into
//! `C` finds only its own files); [`Step::substituted`] puts real folders in.

use std::path::Path;

/// One step of a recipe.
#[derive(Clone, Debug, PartialEq)]
pub enum Step {
    /// `export NAME=VALUE`.
    Env(String, String),
    /// `mkdir -p DIR…`.
    Mkdir(Vec<String>),
    /// `colmap ARGS…`.
    Colmap(Vec<String>),
}

impl Step {
    /// The step with `C` and `R` (whole words, or a word's first path component) replaced by
    /// `export` and `results`.
    pub fn substituted(&self, export: &Path, results: &Path) -> Step {
        let sub = |w: &String| -> String {
            let replace = |dir: &Path, rest: &str| dir.join(rest).display().to_string();
            match w.split_once('/') {
                Some(("C", rest)) => replace(export, rest),
                Some(("R", rest)) => replace(results, rest),
                _ if w == "C" => export.display().to_string(),
                _ if w == "R" => results.display().to_string(),
                _ => w.clone(),
            }
        };
        match self {
            Step::Env(k, v) => Step::Env(k.clone(), v.clone()),
            Step::Mkdir(d) => Step::Mkdir(d.iter().map(sub).collect()),
            Step::Colmap(a) => Step::Colmap(a.iter().map(sub).collect()),
        }
    }
}

/// The steps of the first shell block after the line `heading` in `markdown` (module contract);
/// empty when there is no such heading or block.
pub fn recipe(markdown: &str, heading: &str) -> Vec<Step> {
    let mut lines = markdown.lines().skip_while(|l| l.trim() != heading);
    let _ = lines.by_ref().find(|l| l.trim_start().starts_with("```sh"));
    let mut steps = Vec::new();
    let mut pending = String::new();
    for line in lines {
        if line.trim_start().starts_with("```") {
            break;
        }
        if let Some(head) = line.strip_suffix('\\') {
            pending.push_str(head);
            pending.push(' ');
            continue;
        }
        pending.push_str(line);
        let whole = std::mem::take(&mut pending);
        if whole.contains("...") || whole.contains('…') {
            break;
        }
        let text = whole.split(" #").next().unwrap_or_default().trim();
        let words: Vec<String> = text.split_whitespace().map(str::to_string).collect();
        match words.first().map(String::as_str) {
            Some("export") => {
                for pair in &words[1..] {
                    if let Some((k, v)) = pair.split_once('=') {
                        steps.push(Step::Env(k.into(), v.into()));
                    }
                }
            }
            Some("mkdir") => steps.push(Step::Mkdir(
                words[1..].iter().filter(|w| *w != "-p").cloned().collect(),
            )),
            Some("colmap") => steps.push(Step::Colmap(words[1..].to_vec())),
            _ => {}
        }
    }
    steps
}

/// `docs/mesh.md`, compiled in.
pub const MESH_DOC: &str = include_str!("../../../docs/mesh.md");

/// The heading of the COLMAP route (known poses, `point_triangulator`).
pub const ROUTE: &str = "## The COLMAP route";

/// The heading of the way in (COLMAP's own `mapper`, brought back by `fit --poses`).
pub const WAY_IN: &str = "## The way in: poses and meshes from other tools";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_docs_recipes_read_as_steps() {
        let route = recipe(MESH_DOC, ROUTE);
        assert!(
            route.contains(&Step::Env("QT_QPA_PLATFORM".into(), "offscreen".into())),
            "{route:?}"
        );
        let programs: Vec<&str> = route
            .iter()
            .filter_map(|s| match s {
                Step::Colmap(a) => a.first().map(String::as_str),
                _ => None,
            })
            .collect();
        assert_eq!(
            programs,
            [
                "feature_extractor",
                "exhaustive_matcher",
                "point_triangulator"
            ]
        );
        let way_in = recipe(MESH_DOC, WAY_IN);
        let mapper = way_in
            .iter()
            .find_map(|s| match s {
                Step::Colmap(a) if a[0] == "mapper" => Some(a.clone()),
                _ => None,
            })
            .expect("the way in runs mapper");
        assert!(
            mapper
                .windows(2)
                .any(|w| w == ["--Mapper.ba_refine_focal_length", "0"])
        );
        // COLMAP writes its results beside the export, never inside it
        let c = Path::new("/x/C");
        let r = Path::new("/x/R");
        for step in route.iter().chain(&way_in) {
            if let Step::Colmap(a) = step.substituted(c, r) {
                let out = a
                    .windows(2)
                    .find(|w| w[0] == "--output_path")
                    .map(|w| &w[1]);
                assert!(out.is_none_or(|o| o.starts_with("/x/R")), "{a:?}");
            }
        }
    }
}
