//! Bad frames, thread counts, pose read-back, radiometry sources and the analyser model.

use std::collections::BTreeMap;
use std::path::Path;

use ellipso_model::optics::Stokes;
use ellipso_model::optics::camera_up_from_opencv;
use ellipso_model::optics::measure::SensorIntensities;
use ellipso_model::rig::FlashSpec;
use nalgebra::Vector3;

use super::{SceneSpec, make_session, open, sphere_and_board};
use ellipso_fit::observe::radiometry::{FrameRadiometry, SessionRadiometry};
use ellipso_fit::observe::{
    FrameImages, MosaicFrames, ObserveConfig, ObserveError, extract, extract_from, radiometry_of,
    views_of,
};
use ellipso_fit::shard::Shard;
use ellipso_session::events::SessionEvent;
use ellipso_session::manifest::SessionSource;
use ellipso_session::time::HostTimeUs;
use ellipso_session::writer::SessionAppender;

fn snapshot(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    for sub in ["", "frames"] {
        for e in std::fs::read_dir(dir.join(sub)).unwrap() {
            let p = e.unwrap().path();
            if p.is_file() {
                out.insert(p.display().to_string(), std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

#[test]
fn unreadable_frames_are_skipped_counted_and_left_untouched() {
    let dir = tempfile::tempdir().unwrap();
    let (session_dir, _, mut poses) = make_session(dir.path(), &SceneSpec::paint_mono());
    let frames = session_dir.join("frames");
    // Frame 101: corrupt bytes. Frame 102: values beyond the 12-bit depth, recorded as the
    // session's own (its event's checksum is the new file's, so the depth check is what
    // refuses it, not the provenance check).
    std::fs::write(frames.join("00000101.png"), b"\x89PNG garbage").unwrap();
    let crc = ellipso_session::frame_png::write(
        &frames.join("00000102.png"),
        256,
        200,
        &vec![65535u16; 256 * 200],
    )
    .unwrap();
    let log = session_dir.join("events.jsonl");
    let text = std::fs::read_to_string(&log).unwrap();
    let patched: String = text
        .lines()
        .map(|line| {
            let mut e: serde_json::Value = serde_json::from_str(line).unwrap();
            if e["type"] == "frame" && e["frame_id"] == 102 {
                e["crc64"] = crc.into();
            }
            serde_json::to_string(&e).unwrap() + "\n"
        })
        .collect();
    std::fs::write(&log, patched).unwrap();
    // A pose for a frame that does not exist.
    poses.push((999, poses[0].1));
    let before = snapshot(&session_dir);
    let session = open(&session_dir);
    let (mesh, _) = sphere_and_board(2, 0.1, 11);
    let calls = std::cell::RefCell::new(Vec::new());
    let out = extract(
        &session,
        &mesh,
        &poses,
        &ObserveConfig::default(),
        &|done, total| calls.borrow_mut().push((done, total)),
    )
    .unwrap();
    let skipped: Vec<u64> = out.report.skipped.iter().map(|s| s.frame_id).collect();
    assert_eq!(skipped, vec![101, 102, 999], "{:?}", out.report.skipped);
    assert!(out.report.skipped[0].reason.contains("00000101.png"));
    assert!(out.report.skipped[1].reason.contains("exceeds the 12-bit"));
    assert_eq!(out.report.frames_used, 3);
    assert_eq!(out.report.frames_posed, 6);
    let ids: Vec<u64> = out.samples.views.iter().map(|v| v.frame_id).collect();
    assert_eq!(ids, vec![100, 103, 104]);
    assert!(out.samples.vertices.iter().any(|v| v.samples.len() == 3));
    assert_eq!(calls.borrow().last(), Some(&(5, 5)));
    assert_eq!(before, snapshot(&session_dir), "the session was modified");
}

#[test]
fn output_is_identical_for_any_thread_count_and_frames_in_flight() {
    let dir = tempfile::tempdir().unwrap();
    let (session_dir, _, poses) = make_session(dir.path(), &SceneSpec::paint_mono());
    let session = open(&session_dir);
    let (mesh, _) = sphere_and_board(3, 0.1, 31);
    let run = |threads, frames_in_flight| {
        let config = ObserveConfig {
            threads: Some(threads),
            frames_in_flight,
            ..ObserveConfig::default()
        };
        extract(&session, &mesh, &poses, &config, &|_, _| {}).unwrap()
    };
    let one = run(1, 1);
    let two = run(2, 3);
    assert!(one.report.samples > 1000);
    assert_eq!(one.samples, two.samples);
    assert_eq!(one.report.gates, two.report.gates);
    // The memory account covers the samples and at least one frame.
    assert!(one.report.peak_bytes > one.report.sample_bytes + 256 * 200 * 2);
    let per_sample = std::mem::size_of::<ellipso_fit::data::Sample>() as u64;
    assert_eq!(one.report.sample_bytes, one.report.samples * per_sample);
}

#[test]
fn a_frame_cache_changes_nothing_and_follows_a_mesh_that_moves_out_of_its_crops() {
    let dir = tempfile::tempdir().unwrap();
    let (session_dir, _, poses) = make_session(dir.path(), &SceneSpec::paint_mono());
    // Frame 101 unreadable: never cached, reported at every read.
    std::fs::write(session_dir.join("frames/00000101.png"), b"\x89PNG garbage").unwrap();
    let session = open(&session_dir);
    let config = ObserveConfig::default();
    let radiometry = radiometry_of(&session).unwrap();
    // The sphere alone (its crops are a part of each frame), then 30 mm to the side: its
    // projections leave the first crops.
    let sphere = |shift_m: [f64; 3]| {
        let (dirs, triangles) = ellipso_model::geometry::procedural::icosphere(3);
        let centre = Vector3::from(super::CENTRE) + Vector3::from(shift_m);
        let positions = dirs
            .iter()
            .map(|d| nalgebra::Point3::from(centre + d.into_inner() * super::RADIUS_M))
            .collect();
        let normals = dirs.iter().map(|d| d.into_inner()).collect();
        ellipso_model::geometry::TriangleMesh::new(positions, Some(normals), None, triangles)
            .unwrap()
    };
    let (small, moved) = (sphere([0.0; 3]), sphere([0.03, -0.02, 0.0]));
    let decoding = MosaicFrames::new(&session, &config).unwrap();
    let caching = MosaicFrames::caching(&session, &config).unwrap();
    let run = |mesh, frames: &dyn FrameImages| {
        extract_from(
            &session,
            &radiometry,
            mesh,
            &poses,
            &config,
            Shard::ALL,
            frames,
            &|_, _| {},
        )
        .unwrap()
    };
    let mut held_after = Vec::new();
    for mesh in [&small, &moved, &small] {
        let want = run(mesh, &decoding);
        let got = run(mesh, &caching);
        assert!(want.report.samples > 500, "{}", want.report.samples);
        assert_eq!(got.samples, want.samples);
        assert_eq!(got.report.gates, want.report.gates);
        assert_eq!(got.report.skipped, want.report.skipped);
        assert_eq!(got.report.skipped.len(), 1);
        // The cache is accounted and holds less than the frames do whole.
        let held = caching.held_bytes() as u64;
        assert!(held > 0 && got.report.peak_bytes >= held);
        // 4 readable frames, whole: 5 planes of (256/2)·(200/2) f32
        assert!(
            held < 4 * 5 * (256 / 2) * (200 / 2) * 4,
            "{held} bytes cached"
        );
        held_after.push(held);
    }
    assert_ne!(
        held_after[0], held_after[1],
        "the moved sphere's crops were not replaced"
    );
    // No budget: nothing is kept, and the result is the same.
    let none = MosaicFrames::caching(
        &session,
        &ObserveConfig {
            frame_cache_bytes: 0,
            ..config.clone()
        },
    )
    .unwrap();
    assert_eq!(run(&small, &none).samples, run(&small, &decoding).samples);
    assert_eq!(none.held_bytes(), 0);
}

#[test]
fn poses_round_trip_through_the_session_log() {
    let dir = tempfile::tempdir().unwrap();
    let (session_dir, _, poses) = make_session(dir.path(), &SceneSpec::paint_mono());
    let mut log = SessionAppender::open(&session_dir).unwrap();
    for (id, world_from_camera) in &poses {
        let c = world_from_camera.inverse();
        let r = c.rotation.scaled_axis();
        let t = c.translation.vector;
        log.log(&SessionEvent::Pose {
            t_host_us: HostTimeUs(0),
            frame_id: *id,
            rotation_camera_from_world: [r.x, r.y, r.z],
            translation_camera_from_world_m: [t.x, t.y, t.z],
            rms_px: 0.1,
            tags: 8,
            from: Default::default(),
        })
        .unwrap();
    }
    // A later tracking run rejects frame 102.
    log.log(&SessionEvent::PoseRejected {
        t_host_us: HostTimeUs(1),
        frame_id: 102,
        reason: "too few tags".into(),
        from: Default::default(),
    })
    .unwrap();
    drop(log);
    let read = open(&session_dir).poses().tracked();
    let expected: Vec<_> = poses.iter().filter(|p| p.0 != 102).collect();
    assert_eq!(read.len(), expected.len());
    for ((id, got), (want_id, want)) in read.iter().zip(expected) {
        assert_eq!(id, want_id);
        let d = got.inverse() * want;
        assert!(d.translation.vector.norm() < 1e-12 && d.rotation.angle() < 1e-12);
    }
}

#[test]
fn views_are_built_like_the_renderer() {
    let dir = tempfile::tempdir().unwrap();
    let (session_dir, scene, poses) = make_session(dir.path(), &SceneSpec::paint_mono());
    let views = views_of(&open(&session_dir), &poses).unwrap();
    for ((id, pose), v) in poses.iter().zip(&views) {
        assert_eq!(v.frame_id, *id);
        let r = pose.rotation.inverse().to_rotation_matrix();
        let m = r.matrix();
        let rows = [0, 1, 2].map(|i| [m[(i, 0)], m[(i, 1)], m[(i, 2)]]);
        let up = camera_up_from_opencv(rows);
        assert!((Vector3::from(up) - Vector3::from(v.camera_up_world)).norm() < 1e-12);
        let flash = scene.rig.flash.position_world(pose);
        assert_eq!(v.flash_position_world, <[f64; 3]>::from(flash.coords));
        let axis = v.polariser_axis_world.unwrap();
        // Polariser 0°: along the camera x axis.
        let x = pose.rotation * Vector3::x();
        assert!((Vector3::from(axis) - x).norm() < 1e-12);
    }
}

#[test]
fn radiometry_follows_the_session_source() {
    let dir = tempfile::tempdir().unwrap();
    let (session_dir, scene, _) = make_session(dir.path(), &SceneSpec::paint_mono());
    let mut session = open(&session_dir);
    // Simulator: absolute, the renderer's chain, from the session's record alone.
    let r = radiometry_of(&session).unwrap();
    let camera = &scene.rig.camera;
    let sensor = ellipso_sim::render::radiometry::recorded_sensor(&scene);
    let chain = ellipso_sim::render::radiometry::Radiometry::new(
        camera,
        &scene.rig.flash,
        sensor.radiometry.vignetting_exponent,
    );
    match r.for_frame(camera.exposure_us, camera.gain_db) {
        FrameRadiometry::Absolute(frame) => assert_eq!(frame, chain),
        other => panic!("{other:?}"),
    }
    // The scene file is never read again: a session whose scene is gone keeps its radiometry.
    let mut moved = session.clone();
    moved.manifest.source = SessionSource::Simulator {
        scene: "/nonexistent/scene.toml".into(),
        seed: 1,
    };
    assert_eq!(radiometry_of(&moved).unwrap(), r);
    // A simulator session recorded before the radiometry was: the error names the upgrade.
    let mut old = session.clone();
    old.manifest.rig.as_mut().unwrap().radiometry = None;
    match radiometry_of(&old) {
        Err(ObserveError::Manifest { what, .. }) => {
            assert!(what.contains("ellipso session upgrade"), "{what}")
        }
        other => panic!("{other:?}"),
    }
    // Hardware: relative normaliser, full scale at 10 ms, 0 dB, 0.5 m on the flash axis —
    // as a hardware capture records it, and as a hardware session of an older build (no
    // radiometry recorded) reads.
    session.manifest.source = SessionSource::Hardware {
        trigger_port: "/dev/null".into(),
        camera: "test".into(),
    };
    let rig = session.manifest.rig.as_mut().unwrap();
    *rig = ellipso_session::rig::RigRecord::relative(rig.camera, rig.flash.clone());
    let mut old_hardware = session.clone();
    old_hardware.manifest.rig.as_mut().unwrap().radiometry = None;
    assert_eq!(
        radiometry_of(&old_hardware).unwrap(),
        radiometry_of(&session).unwrap()
    );
    let r = radiometry_of(&session).unwrap();
    let n = |exposure_us, gain_db, d_m, angle_deg: f64| {
        r.for_frame(exposure_us, gain_db)
            .normaliser(d_m, angle_deg.to_radians(), 0.3)
    };
    assert!((n(10_000.0, 0.0, 0.5, 0.0) / 4095.0 - 1.0).abs() < 1e-12);
    assert!((n(5_000.0, 0.0, 0.5, 0.0) / 4095.0 - 0.5).abs() < 1e-12);
    assert!((n(10_000.0, 20.0, 1.0, 0.0) / 4095.0 - 2.5).abs() < 1e-12);
    // cos¹ profile of the scene's flash at 60°.
    assert!((n(10_000.0, 0.0, 0.5, 60.0) / 4095.0 - 0.5).abs() < 1e-12);
    // No flash recorded: no geometry can be built.
    session.manifest.rig.as_mut().unwrap().flash = None;
    assert!(matches!(
        radiometry_of(&session),
        Err(ObserveError::MissingFlash { .. })
    ));
    assert!(views_of(&session, &[]).is_err());
}

#[test]
fn analyser_extinction_is_undone_exactly() {
    let flash = FlashSpec::default();
    let ideal = SessionRadiometry::relative(flash.clone(), 12);
    let leaky = SessionRadiometry {
        analyser_extinction: 1.0 / 50.0,
        ..SessionRadiometry::relative(flash, 12)
    };
    let s = Stokes::new(1.0, 0.3, -0.2, 0.0);
    let exact = SensorIntensities::from_stokes(s).observation();
    // What an analyser with extinction ratio 50 measures (the renderer's model).
    let e = leaky.analyser_extinction;
    let measured = [0.0f64, 45.0, 90.0, 135.0].map(|deg| {
        let (sn, cs) = (2.0 * deg.to_radians()).sin_cos();
        0.5 * ((1.0 + e) * s.s0 + (1.0 - e) * (s.s1 * cs + s.s2 * sn))
    });
    let got = leaky.channels(measured);
    // I^t = I45 + I135 is s0 once the extinction is undone.
    let want = [exact.diffuse, exact.specular, exact.alpha, s.s0];
    for k in 0..4 {
        assert!((got[k] - want[k]).abs() < 1e-12, "{got:?} {want:?}");
    }
    // Ideal analysers: the channels' definitions exactly.
    let i = [0.7, 0.4, 0.2, 0.5];
    let got = ideal.channels(i);
    assert_eq!(got, [2.0 * i[2], i[0] - i[2], i[3] - i[1], i[1] + i[3]]);
}
