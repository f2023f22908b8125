use super::*;

#[test]
fn fresnel_reproduces_the_reference_table() {
    // docs/model.md §8 "Fresnel and diffuse DoP values", η = 1.5, θ = 60°.
    let t = fresnel(1.5, 60.0).unwrap();
    let want = [
        (t.rs, -0.420204),
        (t.rp, -0.042449),
        (t.r_plus, 0.089187),
        (t.r_minus, 0.087385),
        (t.r_cross, 0.017837),
        (t.t_plus, 0.910813),
        (t.t_minus, -0.087385),
    ];
    for (got, w) in want {
        assert!((got - w).abs() < 6e-7, "{got} vs {w}");
    }
}

#[test]
fn dop_matches_table_and_bad_flags_are_named() {
    let v = dop(1.5, 45.0).unwrap();
    assert!((v.dop - 0.043983).abs() < 1e-6);
    assert!(v.d_dop_d_eta > 0.0);
    assert!(dop(0.9, 45.0).unwrap_err().to_string().contains("--eta"));
    assert!(
        fresnel(1.5, 91.0)
            .unwrap_err()
            .to_string()
            .contains("--theta-deg")
    );
    assert!(
        fresnel(f64::NAN, 10.0)
            .unwrap_err()
            .to_string()
            .contains("--eta")
    );
}

fn inputs() -> MuellerInputs {
    MuellerInputs {
        params: PbrdfParams {
            eta: 1.5,
            sigma_s: 0.2,
            sigma_ss: 0.5,
            rho_s: 1.0,
            rho_ss: [0.1; 3],
            rho_d: [0.5, 0.4, 0.3],
        },
        normal: [0.0, 0.0, 1.0],
        to_light: [0.1, 0.0, 1.0],
        to_camera: [-0.1, 0.0, 1.0],
        light_up: None,
        camera_up: None,
    }
}

#[test]
fn mueller_has_the_documented_shape_and_physics() {
    let t = mueller(&inputs()).unwrap();
    assert_eq!(t.diffuse.len(), 3);
    assert_eq!(t.single_scattering.len(), 3);
    let total = t.diffuse[0][0][0] + t.specular[0][0] + t.single_scattering[0][0][0];
    assert!((t.total[0][0][0] - total).abs() < 1e-12);
    assert!(t.diffuse[0][0][0] > t.diffuse[2][0][0], "ρ_d is coloured");
}

#[test]
fn mueller_bad_input_names_the_flag() {
    let err = |f: &dyn Fn(&mut MuellerInputs)| {
        let mut a = inputs();
        f(&mut a);
        mueller(&a).unwrap_err().to_string()
    };
    assert!(err(&|a| a.normal = [0.0; 3]).contains("--normal"));
    assert!(err(&|a| a.to_light = [f64::NAN, 0.0, 1.0]).contains("--to-light"));
    assert!(err(&|a| a.params.eta = 0.5).contains("--eta"));
    assert!(err(&|a| a.params.sigma_s = 1.5).contains("--sigma-s"));
    assert!(err(&|a| a.params.sigma_s = 0.6).contains("--sigma-ss"));
    assert!(err(&|a| a.params.rho_d = [0.1, -1.0, 0.0]).contains("--rho-d"));
    // absurd magnitudes: refused with the range, never NaN
    assert!(err(&|a| a.params.eta = 1e200).contains("[1, 5]"));
    assert!(err(&|a| a.params.rho_s = 1e308).contains("--rho-s must be in [0, 1000]"));
    assert!(err(&|a| a.params.rho_ss[1] = 1e308).contains("--rho-ss"));
    assert!(err(&|a| a.params.rho_d = [0.1, 2.0, 0.0]).contains("--rho-d"));
    assert!(err(&|a| a.light_up = Some([0.0; 3])).contains("--light-up"));
    // a huge or tiny but valid direction is a direction
    for n in [[0.0, 0.0, 1e300], [0.0, 0.0, 1e-300], [1e300, 0.0, 1e300]] {
        let mut a = inputs();
        a.normal = n;
        mueller(&a).unwrap_or_else(|e| panic!("{n:?}: {e}"));
    }
}

#[test]
fn absurd_eta_is_refused_not_nan() {
    for eta in [1e78, 1e155, 5.000_001, f64::INFINITY] {
        assert!(dop(eta, 30.0).unwrap_err().to_string().contains("[1, 5]"));
        assert!(
            fresnel(eta, 30.0)
                .unwrap_err()
                .to_string()
                .contains("[1, 5]")
        );
    }
    for theta in [0.0, 30.0, 89.999, 90.0] {
        dop(5.0, theta).unwrap();
        fresnel(5.0, theta).unwrap();
    }
}
