//! The files of an `ellipso bench accuracy` report: claimed before the sweeps run (so a bad
//! path fails before an hour of fitting, not after it), then written — the Markdown report
//! (`report`), its JSON data (and the end-to-end rows' JSON when they ran) and two
//! accuracy-vs-time plots under `img/` — plus the test that redraws the committed plots from
//! their JSON.
//!
//! Contract: a report of the large run alone has no plots (the plots draw the sweeps, never the
//! large run); every plotted line is one scene and sweep in order of fit time, on a log axis
//! (times floored at 1 ms), non-finite values left out.

use std::path::Path;

use ellipso_report::output::{FileFormat, OutputFile};
use ellipso_report::plot::{LegendPosition, LinePlot};
use ellipso_run_error::{Say, say};

use crate::accuracy::Scores;

use super::{Result, RunResult, report};

/// The report's files: the Markdown report, its JSON data and its two plots in `img/`.
pub(super) struct ReportFiles {
    markdown: OutputFile,
    json: OutputFile,
    /// The end-to-end rows' JSON (`<stem>-end-to-end.json`), written when they ran.
    end_to_end_json: OutputFile,
    eta_png: OutputFile,
    normal_png: OutputFile,
}

impl ReportFiles {
    pub(super) fn claim(path: &Path) -> Result<Self> {
        let dir = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let stem = path.file_stem().map_or("accuracy-vs-time".into(), |s| {
            s.to_string_lossy().to_string()
        });
        let claim = |p: &Path, f| OutputFile::claim(p, "bench-accuracy", f, &[], None);
        Ok(Self {
            markdown: claim(path, FileFormat::MARKDOWN)?,
            json: claim(&dir.join(format!("{stem}.json")), FileFormat::JSON)?,
            end_to_end_json: claim(
                &dir.join(format!("{stem}-end-to-end.json")),
                FileFormat::JSON,
            )?,
            eta_png: claim(
                &dir.join("img").join(format!("{stem}-eta.png")),
                FileFormat::PNG,
            )?,
            normal_png: claim(
                &dir.join("img").join(format!("{stem}-normal.png")),
                FileFormat::PNG,
            )?,
        })
    }
}

pub(super) fn write_report(
    files: &ReportFiles,
    results: &[RunResult],
    end_to_end: &[crate::chain::RunResult],
    total_s: f64,
    command: &str,
    say: &dyn Say,
) -> Result<()> {
    let path = files.markdown.shown();
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let eta_png = files.eta_png.shown().to_path_buf();
    let normal_png = files.normal_png.shown().to_path_buf();
    // The plots draw the sweeps; a report of the large run alone has none to draw.
    let plotted = results.iter().any(|r| r.sweep != "large");
    if plotted {
        plot(
            results,
            &eta_png,
            "η error vs fit time",
            "mean per-vertex η error (%)",
            |s| s.eta_mean_pct,
            end_to_end
                .iter()
                .map(|r| (r.times.fit_s, r.scores.eta_vertex_mean_pct)),
        )?;
        plot(
            results,
            &normal_png,
            "normal error vs fit time",
            "median normal error (°)",
            |s| s.normal_median_deg,
            end_to_end
                .iter()
                .map(|r| (r.times.fit_s, r.scores.normal_median_deg)),
        )?;
    }
    let json = files.json.shown();
    files.json.write(serde_json::to_vec_pretty(results)?)?;
    if !end_to_end.is_empty() {
        files
            .end_to_end_json
            .write(serde_json::to_vec_pretty(end_to_end)?)?;
    }
    let plots = plotted.then_some((eta_png.as_path(), normal_png.as_path()));
    let md = report::markdown(results, end_to_end, total_s, command, plots, dir);
    files.markdown.write(md)?;
    say!(say, "\nreport  {}", path.display());
    if plotted {
        say!(
            say,
            "plots   {}\n        {}",
            eta_png.display(),
            normal_png.display()
        );
    }
    say!(say, "data    {}", json.display());
    Ok(())
}

fn plot(
    results: &[RunResult],
    out: &Path,
    title: &str,
    y_label: &str,
    metric: impl Fn(&Scores) -> f64,
    end_to_end: impl Iterator<Item = (f64, f64)>,
) -> Result<()> {
    let points = results.iter().filter(|r| r.sweep != "large").map(|r| {
        (
            r.scene.as_str(),
            r.sweep.as_str(),
            r.fit_s,
            metric(&r.scores),
        )
    });
    let end_to_end = end_to_end.map(|(s, v)| ("demo", "end to end (rendered frames)", s, v));
    plot_points(points.chain(end_to_end), out, title, y_label)
}

/// The accuracy-vs-time plot of `(scene, sweep, fit seconds, metric)` points: one line per
/// scene and sweep, in order of fit time, on a log time axis.
fn plot_points<'a>(
    points: impl Iterator<Item = (&'a str, &'a str, f64, f64)>,
    out: &Path,
    title: &str,
    y_label: &str,
) -> Result<()> {
    let mut p = LinePlot::new(title)
        .x_label("fit wall time (s, log scale)")
        .y_label(y_label)
        .log_x(true)
        .legend(LegendPosition::TopRight);
    let mut groups: Vec<(String, Vec<(f64, f64)>)> = Vec::new();
    for (scene, sweep, fit_s, value) in points {
        let key = format!("{scene} – {sweep}");
        let point = (fit_s.max(1e-3), value);
        match groups.iter_mut().find(|(k, _)| *k == key) {
            Some((_, pts)) => pts.push(point),
            None => groups.push((key, vec![point])),
        }
    }
    for (k, mut pts) in groups {
        pts.retain(|p| p.1.is_finite());
        pts.sort_by(|a, b| a.0.total_cmp(&b.0));
        p = p.series(k, pts);
    }
    p.save_png(out)?;
    Ok(())
}

/// The committed report's plots redrawn from its JSON (`ELLIPSO_DOCS_IMG=docs/img cargo test
/// -p ellipso-bench redraw_committed`), so a change of drawing needs no re-run of the benchmark.
#[cfg(test)]
mod redraw {
    #[test]
    fn redraw_committed_accuracy_plots() {
        let Some(img) = std::env::var_os("ELLIPSO_DOCS_IMG") else {
            return;
        };
        let docs = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs");
        for stem in ["accuracy-vs-time", "accuracy-bracket"] {
            let text = std::fs::read_to_string(docs.join(format!("{stem}.json"))).unwrap();
            let runs: Vec<serde_json::Value> = serde_json::from_str(&text).unwrap();
            let points = |metric: &'static str| {
                runs.iter().filter(|r| r["sweep"] != "large").map(move |r| {
                    (
                        r["scene"].as_str().unwrap_or("?"),
                        r["sweep"].as_str().unwrap_or("?"),
                        r["fit_s"].as_f64().unwrap_or(f64::NAN),
                        r["scores"][metric].as_f64().unwrap_or(f64::NAN),
                    )
                })
            };
            let img = std::path::Path::new(&img);
            super::plot_points(
                points("eta_mean_pct"),
                &img.join(format!("{stem}-eta.png")),
                "η error vs fit time",
                "mean per-vertex η error (%)",
            )
            .unwrap();
            super::plot_points(
                points("normal_median_deg"),
                &img.join(format!("{stem}-normal.png")),
                "normal error vs fit time",
                "median normal error (°)",
            )
            .unwrap();
        }
    }
}
