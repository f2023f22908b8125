//! `ellipso sim render` tests: files written, PNGs hold exactly the renderer's raw frames, truth
//! and plan JSON parse, bad frame indices are errors naming the range.

use super::*;
use std::fs;

fn scene(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../sim/scenes")
        .join(name)
}

fn render_args(out: &Path) -> RenderArgs {
    RenderArgs {
        scene: scene("sphere.toml"),
        out: out.to_path_buf(),
        frames: Some(2),
        frame: None,
        truth: true,
        width: Some(64),
        height: Some(54),
        supersampling: 1,
        seed: None,
    }
}

#[test]
fn render_writes_raw_pngs_truth_json_and_pixel_truth() {
    let dir = tempfile::tempdir().unwrap();
    render(&render_args(dir.path()), &mut |_, _| {}).unwrap();
    let s = Scene::load(&scene("sphere.toml")).unwrap();
    let r = Renderer::new(
        &s,
        RenderOptions {
            supersampling: 1,
            resolution_px: Some([64, 54]),
            ..RenderOptions::default()
        },
    )
    .unwrap();
    for k in 0..2 {
        let png = image::open(dir.path().join(format!("frame_{k:05}.png"))).unwrap();
        let image::DynamicImage::ImageLuma16(img) = png else {
            panic!("frame {k} is not 16-bit grey");
        };
        assert_eq!((img.width(), img.height()), (64, 54));
        assert_eq!(img.into_raw(), r.render_frame(k).unwrap().raw());
        for stem in ["normal", "depth", "material"] {
            let bytes = fs::read(dir.path().join(format!("{stem}_{k:05}.npy"))).unwrap();
            assert_eq!(&bytes[..6], b"\x93NUMPY");
            assert_eq!((bytes[8] as usize + 10) % 64, 0, "data 64-byte aligned");
        }
    }
    let truth: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(dir.path().join("truth.json")).unwrap()).unwrap();
    let frames = truth["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 2);
    assert_eq!(frames[1]["index"], 1);
    assert_eq!(frames[1]["file"], "frame_00001.png");
    assert_eq!(frames[0]["camera"]["width"], 64);
    assert_eq!(truth["bit_depth"], 12);
    assert!(frames[0]["stage_counts"]["diffuse"].as_u64().unwrap() > 0);
    assert_eq!(
        frames[0]["flash_position_world_m"]
            .as_array()
            .unwrap()
            .len(),
        3
    );
}

#[test]
fn a_frame_past_the_capture_is_an_error_naming_the_range() {
    let dir = tempfile::tempdir().unwrap();
    let mut a = render_args(dir.path());
    a.frames = None;
    a.frame = Some(100_000);
    let e = render(&a, &mut |_, _| {}).unwrap_err().to_string();
    assert!(e.contains("100000") && e.contains("150 frames"), "{e}");
}

#[test]
fn plan_json_lists_stages_and_omissions() {
    let s = Scene::load(&scene("s0_only.toml")).unwrap();
    let v = serde_json::to_value(EffectPlan::from_scene(&s)).unwrap();
    assert_eq!(v["transport"], "scalar");
    let omitted: Vec<&str> = v["omitted"]
        .as_array()
        .unwrap()
        .iter()
        .map(|o| o["stage"].as_str().unwrap())
        .collect();
    assert!(omitted.contains(&"polarisation") && omitted.contains(&"shot_noise"));
}
