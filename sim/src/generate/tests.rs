use super::*;
use crate::scene::Scene;

#[test]
fn same_seed_same_scene_other_seed_other_scene() {
    let options = GenerateOptions::default();
    let a = GeneratedScene::generate(3, options);
    let b = GeneratedScene::generate(3, options);
    let c = GeneratedScene::generate(4, options);
    assert_eq!(a.mesh.positions(), b.mesh.positions());
    assert_eq!(a.mesh.regions(), b.mesh.regions());
    assert_eq!(a.materials, b.materials);
    assert_eq!(
        a.scene_toml("o.ply", "b.toml"),
        b.scene_toml("o.ply", "b.toml")
    );
    assert_ne!(
        a.scene_toml("o.ply", "b.toml"),
        c.scene_toml("o.ply", "b.toml")
    );
    // The options change the camera, never the draws.
    let d = GeneratedScene::generate(
        3,
        GenerateOptions {
            resolution_px: [2448, 2048],
            photo_count: 9,
        },
    );
    assert_eq!(a.materials, d.materials);
    assert_eq!(a.mesh.positions(), d.mesh.positions());
}

#[test]
fn materials_come_from_the_table_and_patches_are_honoured() {
    let mut shapes = std::collections::BTreeSet::new();
    let (mut small, mut pairs, mut dark, mut dark_board) = (0, 0, 0, 0);
    for seed in 0..40 {
        let g = GeneratedScene::generate(seed, GenerateOptions::default());
        shapes.insert(g.shape.name());
        let n = g.materials.len();
        assert!((2..=8).contains(&n), "seed {seed}: {n} materials");
        for (i, m) in g.materials.iter().enumerate() {
            assert!(
                TABLE.contains(&m.row),
                "seed {seed}: {} not in the table",
                m.row.name
            );
            assert_eq!(m.params.eta, m.row.eta);
            assert!(g.materials[..i].iter().all(|o| o.row.name != m.row.name));
            assert!(
                (0.05..=0.5).contains(&m.params.sigma_s),
                "σs {}",
                m.params.sigma_s
            );
            assert!(m.params.sigma_ss >= m.params.sigma_s && m.params.sigma_ss <= 1.0);
            if g.dark_object {
                assert!(m.params.rho_d.iter().all(|&c| c <= 0.06 + 1e-9));
            }
        }
        // Every region id is a material and every patch reaches its share: the grown area is
        // the target less at most one vertex's area (≈ 1/2562 of the sphere, 0.1 %).
        let grown = g.region_fractions();
        let targets: f64 = g.materials.iter().map(|m| m.fraction).sum();
        assert!(
            (targets - 1.0).abs() < 1e-9,
            "seed {seed}: shares sum to {targets}"
        );
        for (m, f) in g.materials.iter().zip(&grown) {
            assert!(m.fraction >= MIN_PATCH_FRACTION - 1e-12);
            assert!(
                *f >= m.fraction - 0.002 && *f >= MIN_PATCH_FRACTION - 0.002,
                "seed {seed}: {} grew to {f:.4} of its {:.4}",
                m.row.name,
                m.fraction
            );
        }
        let least = grown.iter().copied().fold(1.0, f64::min);
        small += usize::from(least < 0.045);
        if let Some([a, b]) = g.same_colour {
            assert_ne!(a, b);
            assert_eq!(g.materials[a].params.rho_d, g.materials[b].params.rho_d);
            pairs += 1;
        }
        dark += usize::from(g.dark_object);
        dark_board += usize::from(g.dark_board);
    }
    assert_eq!(shapes.len(), 3, "every shape kind drawn: {shapes:?}");
    assert!(small > 5 && pairs > 5 && dark > 0 && dark_board > 0);
}

#[test]
fn written_scene_loads_and_rests_on_the_board() {
    let dir = tempfile::tempdir().expect("tempdir");
    for seed in [1, 2] {
        let g = GeneratedScene::generate(seed, GenerateOptions::default());
        let path = g
            .write(&dir.path().join(format!("s{seed}")))
            .expect("write");
        let scene = Scene::load(&path).expect("the generated scene loads");
        assert_eq!(scene.seed, seed);
        assert_eq!(scene.materials.len(), g.materials.len());
        assert_eq!(scene.camera_poses.len(), 50);
        assert_eq!(scene.rig.camera.resolution_px, [612, 512]);
        let crate::scene::ObjectGeometry::Mesh(mesh) = &scene.objects[0].geometry else {
            panic!("a mesh object");
        };
        assert_eq!(mesh.positions().len(), g.mesh.positions().len());
        // The object's lowest point is on the board (z = 0) and its largest radius 32–45 mm.
        let world: Vec<_> = g
            .mesh
            .positions()
            .iter()
            .map(|p| p.z * g.scale + g.lift_m)
            .collect();
        let low = world.iter().copied().fold(f64::INFINITY, f64::min);
        assert!(low.abs() < 1e-12, "lowest point at z = {low}");
        let largest = g
            .mesh
            .positions()
            .iter()
            .map(|p| p.coords.norm() * g.scale)
            .fold(0.0, f64::max);
        assert!(
            (0.032..=0.045).contains(&largest),
            "largest radius {largest}"
        );
    }
}
