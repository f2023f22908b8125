//! Flash-energy bracket: frames lit by a fraction of the full pulse give samples in the same
//! model units as a full frame, the saturation gate judges each frame's own DN, and frames the
//! flash did not light are skipped and counted.

use super::{SceneSpec, make_session_lit, open, sphere_and_board};
use ellipso_fit::observe::{NO_FLASH_REASON, ObserveConfig, SkippedFrame, extract};

/// Three frames from one camera position: full energy, a quarter pulse, no flash.
const ENERGIES: [f64; 3] = [1.0, 0.25, 0.0];

#[test]
fn a_quarter_pulse_frame_gives_the_full_frames_samples_and_unlit_frames_are_skipped() {
    let dir = tempfile::tempdir().unwrap();
    // A glossy sphere exposed so that its highlight clips at full energy.
    let spec = SceneSpec {
        material: "eta = 1.5\nsigma_s = 0.08\nsigma_ss = 0.2\nrho_s = 1.0\n\
                   rho_ss = [0.05, 0.05, 0.05]\nrho_d = [0.3, 0.3, 0.3]",
        exposure_us: 10000.0,
        k1: 0.0,
        cameras: vec![[0.05, 0.02, 0.33]; 3],
        ..SceneSpec::paint_mono()
    };
    let (session_dir, _, poses) = make_session_lit(dir.path(), &spec, Some(&ENERGIES));
    let session = open(&session_dir);
    let energies: Vec<f64> = session.frames.iter().map(|f| f.flash_energy_rel).collect();
    assert_eq!(energies, ENERGIES);
    let (mesh, sphere) = sphere_and_board(3, 0.1, 21);
    let out = extract(
        &session,
        &mesh,
        &poses,
        &ObserveConfig::default(),
        &|_, _| {},
    )
    .unwrap();

    // The unlit frame is skipped with its reason and counted.
    assert_eq!(
        out.report.skipped,
        vec![SkippedFrame {
            frame_id: 102,
            reason: NO_FLASH_REASON.into()
        }]
    );
    assert_eq!((out.report.frames_unlit, out.report.frames_used), (1, 2));
    let views: Vec<u64> = out.samples.views.iter().map(|v| v.frame_id).collect();
    assert_eq!(views, [100, 101]);

    // Every vertex kept in both frames: N of the quarter frame is N/4 of the full frame's, and
    // the samples agree to the frames' quantisation (½ DN per analyser, so at most 1 DN per
    // channel in each frame, divided by that frame's N).
    let (mut both, mut clipped_then_kept) = (0, 0);
    for vs in &out.samples.vertices[..sphere] {
        let full = vs.samples.iter().find(|s| s.view == 0);
        let quarter = vs.samples.iter().find(|s| s.view == 1);
        match (full, quarter) {
            (Some(full), Some(quarter)) => {
                both += 1;
                let n = f64::from(full.normaliser);
                let ratio = f64::from(quarter.normaliser) / n;
                assert!((ratio - 0.25).abs() < 1e-6, "N ratio {ratio}");
                let tolerance = 1.0 / n + 1.0 / (0.25 * n) + 1e-6;
                for (a, b) in full.channels[0].iter().zip(&quarter.channels[0]) {
                    let (a, b) = (f64::from(*a), f64::from(*b));
                    assert!(
                        (a - b).abs() <= tolerance,
                        "vertex {}: full {:?} quarter {:?}",
                        vs.vertex,
                        full.channels[0],
                        quarter.channels[0]
                    );
                }
            }
            // Saturated in the full frame (gated there, in its own DN), kept at a quarter.
            (None, Some(_)) if vs.gates.saturated == 1 => clipped_then_kept += 1,
            _ => {}
        }
    }
    assert!(both > 100, "{both} vertices seen in both frames");
    // (At this small resolution most of the overexposed sphere that clips is seen obliquely,
    // where the footprint gate takes those samples first: 5 vertices remain.)
    assert!(
        clipped_then_kept >= 3,
        "no highlight clipped at full energy and kept at a quarter: {:?}",
        out.report.gates
    );
    // On the sphere the saturation gate fired in the full frame only: its highlight does not
    // reach full scale at 1/4.
    let saturated: u64 = out.samples.vertices[..sphere]
        .iter()
        .map(|v| v.gates.saturated)
        .sum();
    assert_eq!(saturated, clipped_then_kept);
}
