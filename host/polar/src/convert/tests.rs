//! `ellipso polar` end to end: synthetic PNG in, files and summary.json out; bad files rejected
//! with one line naming the problem.

use std::fs;
use std::path::Path;

use ellipso_model::mosaic::{Channel, SensorLayout};
// Warnings are not what these tests look at.
use ellipso_run_error::Silent as Quiet;

use super::pictures::symmetric_range;
use super::*;
use crate::synthetic::mosaic_from_stokes;
use crate::{MaskReason, PixelMask};

fn args(frame: &Path, out: &Path) -> Args {
    Args {
        frame: frame.to_path_buf(),
        out: out.to_path_buf(),
        layout: Some(SensorLayout::MonoPolar),
        bit_depth: None,
        demosaic: DemosaicMethod::Superpixel,
        dark_level: 0.0,
        saturation: None,
        dark_intensity: crate::DEFAULT_DARK_INTENSITY,
        max_residual: None,
        calibration: None,
        npy: false,
    }
}

fn write_png16(path: &Path, w: u32, h: u32, data: Vec<u16>) {
    image::ImageBuffer::<image::Luma<u16>, _>::from_raw(w, h, data)
        .expect("size")
        .save(path)
        .expect("write test PNG");
}

fn error_of(a: Args) -> String {
    match run(&a, &Quiet) {
        Ok(_) => panic!("expected an error"),
        Err(e) => {
            let line = e.to_string();
            assert!(!line.contains('\n'), "one line: {line}");
            line
        }
    }
}

#[test]
fn mono_frame_produces_every_file_and_a_truthful_summary() {
    let dir = tempfile::tempdir().expect("tempdir");
    let frame_path = dir.path().join("frame.png");
    // left half: 30° linearly polarised light; right half has one clipped raw pixel
    let phi = 30f64.to_radians();
    let frame = mosaic_from_stokes(SensorLayout::MonoPolar, 64, 32, 12, |_, _, _| {
        [
            2000.0,
            1000.0 * (2.0 * phi).cos(),
            1000.0 * (2.0 * phi).sin(),
        ]
    })
    .expect("frame");
    let mut data = frame.into_data();
    data[10 * 64 + 41] = 4095;
    write_png16(&frame_path, 64, 32, data);
    let out = dir.path().join("out");
    run(&args(&frame_path, &out), &Quiet).expect("run");

    for f in [
        "s0.png",
        "dolp.png",
        "aolp.png",
        "i_d.png",
        "i_s.png",
        "i_alpha.png",
        "mask.png",
        "mask_bits.png",
        "summary.json",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let s0 = image::open(out.join("s0.png")).expect("s0").into_rgb8();
    // the frame's pixels on top (32 × 16), a colour bar below: a picture readable on its own
    assert!(
        s0.width() >= 32 && s0.height() > 16,
        "{:?}",
        s0.dimensions()
    );
    // a uniform s0/2 = 1000 DN is its own 99.5th percentile: white (the one saturated
    // superpixel is masked and left out of the range)
    assert_eq!(s0.get_pixel(0, 0).0, [255, 255, 255]);
    let dolp = image::open(out.join("dolp.png")).expect("dolp").into_rgb8();
    assert_eq!(dolp.width(), 240, "narrow frames get a legend-wide canvas");
    let want = ellipso_report::colour::dolp_colour(Some(0.5));
    assert!(
        dolp.get_pixel(0, 0)
            .0
            .iter()
            .zip(want)
            .all(|(a, b)| a.abs_diff(b) <= 2),
        "DoLP 0.5 in viridis (whole-DN rounding)"
    );
    // the saturated pixel is masked: grey, not a DoLP colour
    assert_eq!(dolp.get_pixel(20, 5).0, render::MASKED);
    let mask = image::open(out.join("mask_bits.png"))
        .expect("mask")
        .into_luma8();
    assert!(PixelMask(mask.get_pixel(20, 5)[0]).has(MaskReason::Saturated));
    assert_eq!(mask.get_pixel(0, 0)[0], 0);

    let summary: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(out.join("summary.json")).expect("read"))
            .expect("json");
    assert_eq!(summary["layout"], "monopolar");
    assert_eq!(summary["demosaic"]["method"], "superpixel");
    assert_eq!(summary["raw"]["bit_depth"], 12);
    assert!(
        summary["raw"]["bit_depth_source"]
            .as_str()
            .unwrap_or("")
            .contains("default")
    );
    assert_eq!(summary["output"]["width"], 32);
    let band = &summary["bands"][0];
    let sat = band["masked_fraction"]["saturated"]
        .as_f64()
        .unwrap_or(-1.0);
    assert!((sat - 1.0 / 512.0).abs() < 1e-12, "{sat}");
    let mean_dolp = band["mean_dolp_valid"].as_f64().unwrap_or(-1.0);
    assert!((mean_dolp - 0.5).abs() < 1e-3, "{mean_dolp}");
    let aolp = band["mean_aolp_deg_valid"].as_f64().unwrap_or(-1.0);
    assert!((aolp - 30.0).abs() < 0.05, "{aolp}");

    // stokes.exr: the float planes under Mitsuba's names, read back with the exr crate
    let exr = ellipso_report::exr_image::FloatImage::read(&out.join("stokes.exr")).expect("exr");
    assert_eq!((exr.width, exr.height), (32, 16));
    let at = |name: &str| exr.f32_channel(name).unwrap_or_else(|| panic!("{name}"))[0];
    // S0 = I0 + I90 = 2000 DN, S1 = 1000 cos 60°, S2 = 1000 sin 60° (fractions of 4095)
    assert!((at("S0") - 2000.0 / 4095.0).abs() < 1e-6);
    assert!((at("S1") - 500.0 / 4095.0).abs() < 1e-3, "{}", at("S1"));
    assert!((at("S2") - 866.0 / 4095.0).abs() < 1e-3, "{}", at("S2"));
    assert!((at("DoLP") - 0.5).abs() < 1e-3 && (at("AoLP") - phi as f32).abs() < 1e-3);
    assert_eq!(at("Y"), at("S0"));
    assert!((at("I_alpha") + at("S2")).abs() < 1e-7 && (at("I_s") - at("S1")).abs() < 1e-7);
    let exr_mask = match exr.channel("mask") {
        Some(ellipso_report::exr_image::Samples::U32(m)) => m.clone(),
        other => panic!("mask channel: {other:?}"),
    };
    assert!(PixelMask(exr_mask[5 * 32 + 20] as u8).has(MaskReason::Saturated));
    assert!(exr.channel("S0.R").is_none() && exr.channel("S3").is_none());
}

#[test]
fn colour_bilinear_writes_per_band_files() {
    let dir = tempfile::tempdir().expect("tempdir");
    let frame_path = dir.path().join("colour.png");
    let frame = mosaic_from_stokes(SensorLayout::ColourPolar, 16, 8, 12, |_, _, c| match c {
        Some(Channel::Red) => [3000.0, 600.0, 0.0],
        _ => [1000.0, 0.0, -200.0],
    })
    .expect("frame");
    write_png16(&frame_path, 16, 8, frame.into_data());
    let out = dir.path().join("out");
    let mut a = args(&frame_path, &out);
    a.layout = Some(SensorLayout::ColourPolar);
    a.demosaic = DemosaicMethod::Bilinear;
    a.npy = true;
    run(&a, &Quiet).expect("run");
    // full-precision planes: the R band's s0 is exactly 3000/4095 in the interior
    let bytes = fs::read(out.join("s0_r.npy")).expect("npy");
    let header_len = usize::from(u16::from_le_bytes([bytes[8], bytes[9]]));
    let data = &bytes[10 + header_len..];
    assert_eq!(data.len(), 16 * 8 * 4);
    let i = 4 * (5 * 16 + 5);
    let v = f32::from_le_bytes([data[i], data[i + 1], data[i + 2], data[i + 3]]);
    assert!((f64::from(v) - 3000.0 / 4095.0).abs() < 1e-6, "{v}");
    assert!(out.join("mask_b.npy").is_file() && out.join("aolp_rad_g.npy").is_file());
    for f in [
        "s0_r.png",
        "s0_g.png",
        "s0_b.png",
        "s0_rgb.png",
        "aolp_b.png",
        "mask_g.png",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let rgb = image::open(out.join("s0_rgb.png"))
        .expect("rgb")
        .into_rgb8();
    assert!(
        rgb.width() >= 16 && rgb.height() > 8,
        "{:?}",
        rgb.dimensions()
    );
    let px = rgb.get_pixel(5, 5);
    assert!(px[0] > px[1] && px[1] == px[2], "{px:?}");
    let summary = fs::read_to_string(out.join("summary.json")).expect("summary");
    assert!(summary.contains("\"bilinear\"") && summary.contains("\"colourpolar\""));
    assert!(summary.contains("stokes.exr"));
    // stokes.exr per band: the same floats as the .npy planes, S0.R … and the viewer's R, G, B
    let exr = ellipso_report::exr_image::FloatImage::read(&out.join("stokes.exr")).expect("exr");
    let r = exr.f32_channel("S0.R").expect("S0.R");
    assert_eq!(r[5 * 16 + 5], v, "the exact .npy value");
    assert_eq!(exr.f32_channel("R"), Some(r));
    for name in [
        "S1.G",
        "S2.B",
        "DoLP.R",
        "AoLP.G",
        "I_d.B",
        "I_s.R",
        "I_alpha.G",
        "mask.B",
    ] {
        assert!(exr.channel(name).is_some(), "{name}");
    }
    assert!(exr.channel("S0").is_none());
}

#[test]
fn bad_inputs_fail_with_one_line_naming_file_and_problem() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("out");

    let text = dir.path().join("notes.png");
    fs::write(&text, "hello").expect("write");
    let e = error_of(args(&text, &out));
    assert!(e.contains("notes.png") && e.contains("not a PNG"), "{e}");

    let rgb = dir.path().join("rgb.png");
    image::RgbImage::new(4, 4).save(&rgb).expect("write");
    let e = error_of(args(&rgb, &out));
    assert!(
        e.contains("rgb.png") && e.contains("single-channel grey"),
        "{e}"
    );

    let truncated = dir.path().join("truncated.png");
    let full = fs::read(&rgb).expect("read");
    fs::write(&truncated, &full[..full.len() / 2]).expect("write");
    let e = error_of(args(&truncated, &out));
    assert!(
        e.contains("truncated.png") && e.contains("corrupt or truncated"),
        "{e}"
    );

    let odd = dir.path().join("odd.png");
    write_png16(&odd, 5, 4, vec![100; 20]);
    let e = error_of(args(&odd, &out));
    assert!(e.contains("odd.png") && e.contains("5×4"), "{e}");

    let shifted = dir.path().join("left_aligned.png");
    write_png16(&shifted, 4, 4, vec![4096 * 8; 16]);
    let e = error_of(args(&shifted, &out));
    assert!(
        e.contains("exceeds the 12-bit") && e.contains("left-aligned"),
        "{e}"
    );
    let mut a = args(&shifted, &out);
    a.bit_depth = Some(16);
    run(&a, &Quiet).expect("16-bit accepted");

    let eight = dir.path().join("eight.png");
    image::GrayImage::new(4, 4).save(&eight).expect("write");
    let mut a = args(&eight, &out);
    a.bit_depth = Some(12);
    let e = error_of(a);
    assert!(e.contains("PNG 8-bit but --bit-depth 12"), "{e}");

    let mut a = args(&dir.path().join("missing.png"), &out);
    a.saturation = Some(10);
    let e = error_of(a);
    assert!(
        e.contains("missing.png") && e.contains("cannot open"),
        "{e}"
    );
}

#[test]
fn bit_depth_flag_accepts_only_camera_depths() {
    assert_eq!(parse_bit_depth("12"), Ok(12));
    assert!(parse_bit_depth("14").is_err());
    assert!(parse_bit_depth("x").is_err());
}

#[test]
fn display_range_ignores_masked_pixels_and_never_is_zero() {
    let masks = [PixelMask::VALID, PixelMask::only(MaskReason::Saturated)];
    assert_eq!(symmetric_range(&[0.2, -9.0], &masks), 0.2);
    assert_eq!(symmetric_range(&[0.0, 0.0], &masks), 1e-6);
    assert_eq!(symmetric_range(&[], &[]), 1e-6);
}

/// The synthetic sphere of the docs/polar.md example: DoLP growing toward the limb, AoLP along
/// the normal azimuth, a clipped highlight, a weakly polarised 20° background (12-bit DN).
fn documented_sphere(x: u32, y: u32) -> [f64; 3] {
    let (cx, cy, radius) = (240.0, 160.0, 130.0);
    let (dx, dy) = (f64::from(x) - cx, cy - f64::from(y)); // dy toward image-up
    let d = dx.hypot(dy) / radius;
    let (s0, p, phi) = if d < 1.0 {
        if (dx + 40.0).hypot(dy - 40.0) < 10.0 {
            (9000.0, 0.9, 0.0)
        } else {
            (
                3000.0 * (1.0 - d * d).sqrt() + 300.0,
                0.6 * d.powi(3),
                dy.atan2(dx),
            )
        }
    } else {
        (400.0, 0.05, 20f64.to_radians())
    };
    [s0, s0 * p * (2.0 * phi).cos(), s0 * p * (2.0 * phi).sin()]
}

#[test]
fn documented_sphere_example_reproduces() {
    let dir = tempfile::tempdir().expect("tempdir");
    let frame_path = dir.path().join("sphere.png");
    let frame = mosaic_from_stokes(SensorLayout::MonoPolar, 480, 320, 12, |x, y, _| {
        documented_sphere(x, y)
    })
    .expect("frame");
    write_png16(&frame_path, 480, 320, frame.into_data());
    let out = dir.path().join("out");
    let mut a = args(&frame_path, &out);
    a.max_residual = Some(0.05);
    run(&a, &Quiet).expect("run");
    // the pictures of docs/polar.md: `ELLIPSO_DOCS_IMG=docs/img` (a folder) copies them there
    if let Some(img) = std::env::var_os("ELLIPSO_DOCS_IMG") {
        for stem in ["aolp", "i_s", "dolp", "mask"] {
            let to = Path::new(&img).join(format!("polar-example-{stem}.png"));
            fs::copy(out.join(format!("{stem}.png")), &to).expect("copy to ELLIPSO_DOCS_IMG");
        }
    }
    let summary: serde_json::Value =
        serde_json::from_str(&fs::read_to_string(out.join("summary.json")).expect("read"))
            .expect("json");
    let band = &summary["bands"][0];
    let get = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::NAN);
    // the figures quoted in docs/polar.md
    assert!((get(&band["masked_fraction"]["saturated"]) - 0.0022).abs() < 2e-4);
    let ring = get(&band["masked_fraction"]["inconsistent"]);
    assert!(
        ring > 0.002 && ring < 0.005,
        "IFoV ring at the limb: {ring}"
    );
    assert!((get(&band["mean_aolp_deg_valid"]) - 18.48).abs() < 0.1);
    assert!((get(&band["mean_dolp_valid"]) - 0.116).abs() < 0.002);
    // the ring is on the limb, not inside the sphere: mask pixel at the centre is valid,
    // and some pixel within one superpixel of the limb is inconsistent
    let mask = image::open(out.join("mask_bits.png"))
        .expect("mask")
        .into_luma8();
    assert_eq!(mask.get_pixel(120, 80)[0], 0);
    let limb_flags = (0..360)
        .filter(|k| {
            let t = f64::from(*k).to_radians();
            let (x, y) = (120.0 + 65.0 * t.cos(), 80.0 - 65.0 * t.sin());
            let m = PixelMask(mask.get_pixel(x.round() as u32, y.round() as u32)[0]);
            m.has(MaskReason::Inconsistent)
        })
        .count();
    assert!(limb_flags > 0, "no inconsistent pixel on the limb");
}

#[test]
fn calibration_file_is_applied_and_recorded_or_rejected_by_name() {
    let dir = tempfile::tempdir().expect("tempdir");
    let frame_path = dir.path().join("frame.png");
    let frame = mosaic_from_stokes(SensorLayout::MonoPolar, 8, 8, 12, |_, _, _| {
        [2000.0, 600.0, -400.0]
    })
    .expect("frame");
    write_png16(&frame_path, 8, 8, frame.into_data());
    let out = dir.path().join("out");

    let good = dir.path().join("cal.json");
    fs::write(
        &good,
        r#"{"angle_deg":[0,45,90,135],"extinction_ratio":[1e9,1e9,1e9,1e9],"gain":[1,1,1,1]}"#,
    )
    .expect("write");
    let mut a = args(&frame_path, &out);
    a.calibration = Some(good);
    run(&a, &Quiet).expect("run");
    let summary = fs::read_to_string(out.join("summary.json")).expect("summary");
    assert!(summary.contains("\"extinction_ratio\""), "{summary}");

    let degenerate = dir.path().join("same_angles.json");
    fs::write(
        &degenerate,
        r#"{"angle_deg":[0,0,0,0],"extinction_ratio":[30,30,30,30],"gain":[1,1,1,1]}"#,
    )
    .expect("write");
    let mut a = args(&frame_path, &out);
    a.calibration = Some(degenerate);
    let e = error_of(a);
    assert!(
        e.contains("same_angles.json") && e.contains("cannot separate"),
        "{e}"
    );

    let garbage = dir.path().join("garbage.json");
    fs::write(&garbage, "{\"angle_deg\": 3}").expect("write");
    let mut a = args(&frame_path, &out);
    a.calibration = Some(garbage);
    let e = error_of(a);
    assert!(
        e.contains("garbage.json") && e.contains("not an analyser calibration"),
        "{e}"
    );
}

#[test]
fn bit_depth_defaults_and_warnings_are_recorded() {
    let dir = tempfile::tempdir().expect("tempdir");
    let out = dir.path().join("out");
    let read_summary = |out: &Path| -> serde_json::Value {
        serde_json::from_str(&fs::read_to_string(out.join("summary.json")).expect("read"))
            .expect("json")
    };

    // 8-bit PNG: 8-bit data, full scale 255
    let eight = dir.path().join("eight.png");
    image::GrayImage::from_raw(4, 4, vec![200; 16])
        .expect("size")
        .save(&eight)
        .expect("write");
    run(&args(&eight, &out), &Quiet).expect("8-bit");
    let s = read_summary(&out);
    assert_eq!(s["raw"]["bit_depth"], 8);
    assert_eq!(s["levels"]["full_scale_dn"], 255);
    assert_eq!(s["raw"]["warnings"].as_array().map(Vec::len), Some(0));

    // 16-bit PNG whose values fit 10 bits: still 12-bit by default, with a warning saying so
    let dim = dir.path().join("dim.png");
    write_png16(&dim, 4, 4, vec![900; 16]);
    run(&args(&dim, &out), &Quiet).expect("dim");
    let s = read_summary(&out);
    assert_eq!(s["raw"]["bit_depth"], 12);
    let warning = s["raw"]["warnings"][0].as_str().unwrap_or("").to_string();
    assert!(warning.contains("--bit-depth 10"), "{warning}");

    // the flag wins and the summary says why
    let mut a = args(&dim, &out);
    a.bit_depth = Some(10);
    run(&a, &Quiet).expect("flag");
    let s = read_summary(&out);
    assert_eq!(s["raw"]["bit_depth"], 10);
    assert_eq!(s["raw"]["bit_depth_source"], "--bit-depth");

    // levels that contradict the bit depth fail in one line naming the file
    let mut a = args(&dim, &out);
    a.dark_level = 5000.0;
    let e = error_of(a);
    assert!(e.contains("dim.png") && e.contains("dark level"), "{e}");
    let mut a = args(&dim, &out);
    a.saturation = Some(9000);
    let e = error_of(a);
    assert!(
        e.contains("dim.png") && e.contains("saturation level 9000"),
        "{e}"
    );
}

/// The same 12-bit mono frame as 16-bit PNG, 16-bit TIFF, float TIFF (normalised), `.npy` u2
/// and `.npy` f4 (DN) gives the same Stokes planes; a colour frame without `--layout` is
/// detected as colour, and a frame that is neither clearly is refused, never read as mono.
#[test]
fn tiff_npy_and_float_mosaics_read_like_png_and_colour_is_never_read_as_mono() {
    let dir = tempfile::tempdir().expect("tempdir");
    let phi = 30f64.to_radians();
    let frame = mosaic_from_stokes(SensorLayout::MonoPolar, 64, 32, 12, |x, _, _| {
        let s0 = 1500.0 + 8.0 * x as f64;
        [
            s0,
            0.4 * s0 * (2.0 * phi).cos(),
            0.4 * s0 * (2.0 * phi).sin(),
        ]
    })
    .expect("frame");
    let data = frame.into_data();
    let png = dir.path().join("f.png");
    write_png16(&png, 64, 32, data.clone());
    let tiff16 = dir.path().join("f16.tif");
    let tiff32 = dir.path().join("f32.tiff");
    {
        use tiff::encoder::{TiffEncoder, colortype};
        let mut e = TiffEncoder::new(fs::File::create(&tiff16).unwrap()).unwrap();
        e.write_image::<colortype::Gray16>(64, 32, &data).unwrap();
        let floats: Vec<f32> = data.iter().map(|v| f32::from(*v) / 4095.0).collect();
        let mut e = TiffEncoder::new(fs::File::create(&tiff32).unwrap()).unwrap();
        e.write_image::<colortype::Gray32Float>(64, 32, &floats)
            .unwrap();
    }
    let npy16 = dir.path().join("f16.npy");
    ellipso_report::npy::write(&npy16, &[32, 64], &data).unwrap();
    let npyf = dir.path().join("ff.npy");
    let dn: Vec<f32> = data.iter().map(|v| f32::from(*v)).collect();
    ellipso_report::npy::write(&npyf, &[32, 64], &dn).unwrap();
    let s0_of = |frame: &Path, bit_depth: Option<u8>| {
        let out = dir
            .path()
            .join(frame.file_name().unwrap())
            .with_extension("out");
        let mut a = args(frame, &out);
        a.layout = None;
        a.bit_depth = bit_depth;
        a.npy = true;
        let w = write(&a, &Quiet).expect("write");
        assert!(w.headline.contains("MonoPolar"), "{}", w.headline);
        let bytes = fs::read(out.join("s0.npy")).unwrap();
        ellipso_report::npy::decode(&bytes).unwrap().data
    };
    let reference = s0_of(&png, None);
    for (f, depth) in [
        (&tiff16, None),
        (&npy16, None),
        (&npyf, Some(12)),
        (&tiff32, Some(12)),
    ] {
        let s0 = s0_of(f, depth);
        let worst = s0
            .iter()
            .zip(&reference)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(worst < 1e-6, "{}: s0 differs by {worst}", f.display());
    }
    // a colour frame (green twice as sensitive as red and blue) without --layout: detected
    let colour = mosaic_from_stokes(SensorLayout::ColourPolar, 64, 32, 12, |_, _, c| {
        let k = if c == Some(Channel::Green) { 2.0 } else { 1.0 };
        [k * 1000.0, 0.0, 0.0]
    })
    .expect("colour");
    let cpath = dir.path().join("colour.png");
    write_png16(&cpath, 64, 32, colour.into_data());
    let mut a = args(&cpath, &dir.path().join("c"));
    a.layout = None;
    let w = write(&a, &Quiet).expect("colour frame");
    assert!(
        w.headline.contains("ColourPolar") && w.headline.contains("detected"),
        "{}",
        w.headline
    );
    // neither clearly: red and blue blocks off by a little, greens equal → refused
    // block gains R 1.06, G 1.00 and 1.02, B 1.06: red/blue vs green 0.097, green vs green 0.019
    let unclear: Vec<u16> = (0..64 * 32)
        .map(|i| {
            let (x, y) = (i % 64, i / 64);
            let k = [[1.06, 1.0], [1.02, 1.06]][(y / 2) % 2][(x / 2) % 2];
            (1000.0 * k) as u16
        })
        .collect();
    let upath = dir.path().join("unclear.png");
    write_png16(&upath, 64, 32, unclear);
    let mut a = args(&upath, &dir.path().join("u"));
    a.layout = None;
    let e = error_of(a);
    assert!(e.contains("--layout"), "{e}");
    // a colour TIFF and a 3-D .npy are refused by name
    let rgb = dir.path().join("rgb.npy");
    ellipso_report::npy::write(&rgb, &[4, 4, 3], &[0u8; 48]).unwrap();
    let e = error_of(args(&rgb, &dir.path().join("r")));
    assert!(e.contains("2-D"), "{e}");
}
