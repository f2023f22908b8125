//! Issue 46 item 8: impossible rig values are refused by their key.

use super::*;
use crate::rig::tests::complete;

fn refused(edit: impl Fn(&mut RigRecord), key: &str) {
    let mut rig = complete();
    edit(&mut rig);
    let e = check(&rig).unwrap_err();
    assert_eq!(e.key, key, "{e}");
    assert!(e.to_string().contains(key), "{e}");
}

fn absolute(rig: &mut RigRecord) -> &mut CameraRadiometry {
    match rig.radiometry.as_mut() {
        Some(RadiometryRecord::Absolute(r)) => r,
        _ => unreachable!("the test record is absolute"),
    }
}

#[test]
fn a_complete_record_passes() {
    check(&complete()).unwrap();
}

#[test]
fn every_impossible_value_of_the_issue_is_refused_by_its_key() {
    let intensity = "rig.flash.radiant_intensity_w_per_sr";
    for v in [0.0, -0.5, 1e308, f64::NAN] {
        refused(
            |r| r.flash.as_mut().unwrap().radiant_intensity_w_per_sr = v,
            intensity,
        );
    }
    refused(
        |r| r.flash.as_mut().unwrap().offset_m = [1e6, 0.0, 0.0],
        "rig.flash.offset_m",
    );
    refused(
        |r| r.flash.as_mut().unwrap().profile.exponent = Some(-5.0),
        "rig.flash.profile.exponent",
    );
    refused(|r| absolute(r).f_number = 0.0, "rig.radiometry.f_number");
    refused(
        |r| absolute(r).quantum_efficiency = 0.0,
        "rig.radiometry.quantum_efficiency",
    );
    refused(
        |r| absolute(r).full_well_e = -1.0,
        "rig.radiometry.full_well_e",
    );
    refused(
        |r| absolute(r).pixel_pitch_um = 1e308,
        "rig.radiometry.pixel_pitch_um",
    );
    refused(
        |r| absolute(r).vignetting_exponent = Some(-50.0),
        "rig.radiometry.vignetting_exponent",
    );
    refused(
        |r| r.noise.as_mut().unwrap().read_noise_e = -3.0,
        "rig.noise.read_noise_e",
    );
    refused(
        |r| r.noise.as_mut().unwrap().read_noise_e = 1e308,
        "rig.noise.read_noise_e",
    );
    refused(
        |r| r.noise.as_mut().unwrap().gain_db = 1000.0,
        "rig.noise.gain_db",
    );
    refused(
        |r| r.noise.as_mut().unwrap().full_well_e = 1.0,
        "rig.noise.full_well_e",
    );
    for v in [0.0, -300.0] {
        refused(
            |r| r.analyser_extinction_ratio = Some(v),
            "rig.analyser_extinction_ratio",
        );
    }
}
