//! k-means, automatic k and feature scaling on synthetic feature blobs.

use super::*;
use rand_distr::{Distribution, Normal};

/// `per` points around each centre with isotropic noise `sd`.
fn blobs(centres: &[Feature], per: usize, sd: f64, seed: u64) -> (Vec<Feature>, Vec<usize>) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let noise = Normal::new(0.0, sd).unwrap();
    let mut pts = Vec::new();
    let mut truth = Vec::new();
    for (c, centre) in centres.iter().enumerate() {
        for _ in 0..per {
            pts.push(centre.map(|v| v + noise.sample(&mut rng)));
            truth.push(c);
        }
    }
    (pts, truth)
}

/// Fraction of points whose cluster's majority truth label matches their own.
fn purity(labels: &[usize], truth: &[usize], k: usize, k_true: usize) -> f64 {
    let mut table = vec![vec![0usize; k_true]; k];
    for (&l, &t) in labels.iter().zip(truth) {
        table[l][t] += 1;
    }
    let agree: usize = table
        .iter()
        .map(|row| row.iter().max().copied().unwrap_or(0))
        .sum();
    agree as f64 / labels.len() as f64
}

const CENTRES: [Feature; 3] = [
    [1.0, 1.0, 1.0, 3.0],
    [2.0, 0.5, 0.2, 3.4],
    [0.2, 0.4, 1.8, 4.2],
];

#[test]
fn kmeans_separates_well_separated_blobs_and_is_deterministic() {
    let (pts, truth) = blobs(&CENTRES, 120, 0.05, 1);
    let p = kmeans(&pts, 3, 4, 100, 7);
    assert_eq!(p.centroids.len(), 3);
    assert_eq!(purity(&p.labels, &truth, 3, 3), 1.0);
    for c in &CENTRES {
        let (_, d2) = nearest(c, &p.centroids);
        assert!(d2.sqrt() < 0.03, "centroid off by {}", d2.sqrt());
    }
    assert_eq!(p.sizes.iter().sum::<usize>(), pts.len());
    // Same seed, same result, bit for bit (also on a 1-thread pool).
    let again = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap()
        .install(|| kmeans(&pts, 3, 4, 100, 7));
    assert_eq!(p, again);
}

#[test]
fn automatic_k_finds_three_blobs_and_one_blob() {
    let (pts, _) = blobs(&CENTRES, 150, 0.08, 2);
    let config = ClusterConfig::default();
    let s = select(&pts, &config);
    assert_eq!(s.partition.centroids.len(), 3, "tried {:?}", s.tried);
    assert!(s.silhouette.unwrap() > 0.7);
    // One isotropic blob: no k ≥ 2 reaches "reasonable structure".
    let (one, _) = blobs(&CENTRES[..1], 400, 0.08, 3);
    let s = select(&one, &config);
    assert_eq!(s.partition.centroids.len(), 1, "tried {:?}", s.tried);
    assert!(s.silhouette.is_none());
}

#[test]
fn degenerate_inputs_do_not_panic() {
    assert!(kmeans(&[], 3, 2, 10, 0).centroids.is_empty());
    let s = select(&[], &ClusterConfig::default());
    assert!(s.partition.centroids.is_empty());
    let single = [[0.5, 0.5, 0.5, 3.0]];
    let s = select(&single, &ClusterConfig::default());
    assert_eq!(s.partition.sizes, vec![1]);
    // Identical features: one cluster even when more are asked for.
    let same = vec![[0.3, 0.2, 0.1, 3.0]; 50];
    let p = kmeans(&same, 4, 3, 50, 0);
    assert_eq!(p.sizes, vec![50]);
    assert!(p.inertia < 1e-20);
    let fixed = ClusterConfig {
        k: Some(5),
        ..ClusterConfig::default()
    };
    assert_eq!(select(&same, &fixed).partition.centroids.len(), 1);
    assert_eq!(
        select(&same, &ClusterConfig::default()).partition.sizes,
        vec![50]
    );
}

#[test]
fn feature_scaling_clips_and_floors() {
    // Two materials: λ₁ is dominated by the material difference.
    let mut rho = vec![[0.2, 0.2, 0.2]; 50];
    rho.extend(vec![[0.6, 0.6, 0.6]; 50]);
    rho.push([100.0, 0.2, 0.2]); // an outlier, clipped at 10 × max median
    let s = FeatureScaling::from_members(&rho);
    assert!((s.rho_d_clip - 6.0).abs() < 1e-12, "{s:?}");
    let f = s.feature([100.0, 0.2, 0.2], 5.0);
    assert!((f[0] - 6.0 * s.rho_d_scale).abs() < 1e-12);
    assert_eq!(f[3], 6.0);
    // √λ₁ of a ±0.2 split along (1,1,1)/√3: 0.2·√3 ≈ 0.346 (outlier adds a little).
    assert!(
        s.rho_d_scale > 1.0 / 0.6 && s.rho_d_scale < 1.0 / 0.3,
        "{s:?}"
    );
    // One material, no spread: the floor (0.5 × max median) sets the scale.
    let s = FeatureScaling::from_members(&[[0.4, 0.3, 0.2]; 20]);
    assert!((s.rho_d_scale - 1.0 / 0.2).abs() < 1e-9, "{s:?}");
    // All zero: identity, finite.
    let s = FeatureScaling::from_members(&[[0.0; 3]; 5]);
    assert_eq!(s.rho_d_scale, 1.0);
    assert!(s.feature([0.0; 3], 1.5).iter().all(|v| v.is_finite()));
}

#[test]
fn min_cluster_size_scales_with_the_mesh() {
    assert_eq!(effective_min_cluster_vertices(100, 100_000), 100);
    assert_eq!(effective_min_cluster_vertices(100, 5000), 100);
    assert_eq!(effective_min_cluster_vertices(100, 600), 12);
    assert_eq!(effective_min_cluster_vertices(100, 10), 5);
    assert_eq!(effective_min_cluster_vertices(3, 10), 3);
}

#[test]
fn gate_groups_keep_materials_apart_and_join_the_splits_of_one() {
    // Three materials: every cluster its own group.
    let (pts, _) = blobs(&CENTRES, 150, 0.08, 4);
    let p = kmeans(&pts, 3, 4, 100, 7);
    assert_eq!(separated_groups(&pts, &p), vec![0, 1, 2]);
    // Two materials 0.5 apart with tight spreads: still two.
    let close = [[1.0, 1.0, 1.0, 3.0], [1.5, 1.0, 1.0, 3.0]];
    let (pts, _) = blobs(&close, 200, 0.02, 5);
    let p = kmeans(&pts, 2, 4, 100, 7);
    assert_eq!(separated_groups(&pts, &p), vec![0, 1]);
    // One material forced into three clusters: one group, whatever the split.
    let (one, _) = blobs(&CENTRES[..1], 400, 0.08, 6);
    let p = kmeans(&one, 3, 4, 100, 7);
    assert_eq!(p.centroids.len(), 3);
    assert_eq!(separated_groups(&one, &p), vec![0, 0, 0]);
    // One material plus a sparse, wide tail beside it (vertices whose albedo the data leave
    // open): the tail's cluster joins the material.
    let (mut pts, _) = blobs(&CENTRES[..1], 400, 0.05, 7);
    let (tail, _) = blobs(&[[1.8, 1.8, 1.8, 3.0]], 40, 0.4, 8);
    pts.extend(tail);
    let p = kmeans(&pts, 2, 4, 100, 7);
    assert_eq!(p.centroids.len(), 2);
    assert_eq!(separated_groups(&pts, &p), vec![0, 0]);
}

#[test]
fn automatic_k_joins_the_splits_of_one_material_and_keeps_materials_apart() {
    // One grey material whose albedo drifts over the object (model error, a shading bias):
    // spread along one direction, unimodal. The silhouette takes a k ≥ 2 split; its clusters
    // are not separated, so they are joined into one.
    let mut rng = ChaCha8Rng::seed_from_u64(9);
    let drift = Normal::new(0.0, 0.15).unwrap();
    let noise = Normal::new(0.0, 0.01).unwrap();
    let one: Vec<Feature> = (0..600)
        .map(|_| {
            let d = drift.sample(&mut rng);
            [
                2.0 + d + noise.sample(&mut rng),
                2.0 + d + noise.sample(&mut rng),
                2.0 + d + noise.sample(&mut rng),
                3.0 + noise.sample(&mut rng),
            ]
        })
        .collect();
    let config = ClusterConfig::default();
    let s = select(&one, &config);
    let split = s.tried.iter().filter_map(|t| t.1).fold(0.0, f64::max);
    assert!(split >= config.min_silhouette, "tried {:?}", s.tried);
    assert_eq!(s.partition.centroids.len(), 1, "tried {:?}", s.tried);
    assert!(s.joined_from.is_some_and(|k| k >= 2));
    assert!(s.silhouette.is_none());
    // Joined down to one, the partition is k-means' own k = 1 (the members' mean), bit for bit.
    assert_eq!(s.partition, kmeans(&one, 1, 1, 100, 0));
    // Two such materials far apart: the splits inside each are joined, the two stay apart.
    let mut two = one.clone();
    two.extend(
        one.iter()
            .map(|p| [p[0] + 3.0, p[1] + 3.0, p[2] + 3.0, p[3] + 1.0]),
    );
    let s = select(&two, &config);
    assert_eq!(s.partition.centroids.len(), 2, "tried {:?}", s.tried);
    assert_eq!(s.partition.sizes, vec![600, 600]);
    assert!(s.silhouette.unwrap() > 0.8);
    // Three separated blobs are left as the silhouette chose them.
    let (pts, _) = blobs(&CENTRES, 150, 0.08, 2);
    let s = select(&pts, &config);
    assert_eq!((s.partition.centroids.len(), s.joined_from), (3, None));
}

#[test]
fn joining_keeps_every_point_and_recomputes_the_centres() {
    let (one, _) = blobs(&CENTRES[..1], 400, 0.08, 6);
    let forced = kmeans(&one, 3, 4, 100, 7);
    let joined = join_unseparated(&one, forced);
    assert_eq!(joined.centroids.len(), 1);
    assert_eq!(joined.sizes, vec![400]);
    assert!(joined.labels.iter().all(|&l| l == 0));
    let mean: Vec<f64> = (0..FEATURE_DIM)
        .map(|d| one.iter().map(|p| p[d]).sum::<f64>() / 400.0)
        .collect();
    for (c, m) in joined.centroids[0].iter().zip(&mean) {
        assert!((c - m).abs() < 1e-12);
    }
    let inertia: f64 = one
        .iter()
        .map(|p| distance_sq(p, &joined.centroids[0]))
        .sum();
    assert!((joined.inertia - inertia).abs() < 1e-9 * inertia);
}

#[test]
fn same_colour_materials_apart_in_eta_stay_apart_whatever_the_colour_noise() {
    // Two materials of one colour whose η differ by 0.26 (feature 0.52), η noise 0.023
    // (feature 0.046), the albedo's noise 0.08 per channel: the old rule on the full distance
    // (centres within 4 × the sum of the median distances, ≈ 1.2) joined them; the distance
    // across the centres' line does not count.
    let mut rng = ChaCha8Rng::seed_from_u64(21);
    let colour = Normal::new(0.0, 0.08).unwrap();
    let eta = Normal::new(0.0, 0.046).unwrap();
    let mut pts = Vec::new();
    for (centre, n) in [(3.18, 700), (3.70, 250)] {
        for _ in 0..n {
            pts.push([
                2.0 + colour.sample(&mut rng),
                0.9 + colour.sample(&mut rng),
                0.1 + colour.sample(&mut rng),
                centre + eta.sample(&mut rng),
            ]);
        }
    }
    let p = kmeans(&pts, 2, 4, 100, 7);
    let (ratio, threshold) = split_ratio(&pts, &p, 0, 1);
    assert!(ratio > 2.0 * threshold, "{ratio} vs {threshold}");
    assert_eq!(separated_groups(&pts, &p), vec![0, 1]);
    let s = select(&pts, &ClusterConfig::default());
    assert_eq!(s.partition.centroids.len(), 2, "tried {:?}", s.tried);
}

#[test]
fn a_flat_spread_cut_in_two_is_one_material_at_every_size() {
    // The uniform density is the unimodal shape whose halves lie farthest apart: at the 99 %
    // level of `SPLIT_RATIO_NOISE` no more than a few of 200 draws may separate.
    let mut separated = 0;
    for seed in 0..200u64 {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let n = [40, 100, 400][seed as usize % 3];
        let pts: Vec<Feature> = (0..n)
            .map(|_| [1.0, 1.0, 1.0, 3.0 + rng.random_range(-0.5..0.5)])
            .collect();
        let p = kmeans(&pts, 2, 1, 100, seed);
        if p.centroids.len() == 2 && separated_groups(&pts, &p) == vec![0, 1] {
            separated += 1;
        }
    }
    assert!(separated <= 6, "{separated} of 200 flat spreads split");
    // Two equal normal materials 5σ apart are two at 100 members each.
    let (pts, _) = blobs(&[[1.0, 1.0, 1.0, 3.0], [1.0, 1.0, 1.0, 3.5]], 100, 0.1, 3);
    let p = kmeans(&pts, 2, 4, 100, 7);
    assert_eq!(separated_groups(&pts, &p), vec![0, 1]);
}

#[test]
fn a_few_outlying_features_do_not_veto_the_split_of_two_materials() {
    // Two materials (one colour, η 1.59 and 1.85; the feature holds 2η) of 300 and 60
    // vertices, and 5 vertices far off in colour (a blend at a silhouette): every k-means
    // partition gives those a centre of their own, under the minimum size, so no k qualified
    // and the two materials were joined. Dropping that centre keeps the materials' split.
    let (mut pts, mut truth) = blobs(&[[2.0, 0.87, 0.12, 3.18]], 300, 0.01, 21);
    let (minority, _) = blobs(&[[2.0, 0.87, 0.12, 3.70]], 60, 0.01, 22);
    pts.extend(&minority);
    truth.extend(std::iter::repeat_n(1, minority.len()));
    let (outliers, _) = blobs(&[[5.0, 3.0, 2.0, 3.2]], 5, 0.01, 23);
    pts.extend(&outliers);
    truth.extend(std::iter::repeat_n(0, outliers.len()));
    let config = ClusterConfig::default();
    let min_size = effective_min_cluster_vertices(config.min_cluster_vertices, pts.len());
    assert!(outliers.len() < min_size && minority.len() >= min_size);
    let s = select(&pts, &config);
    assert_eq!(s.partition.centroids.len(), 2, "tried {:?}", s.tried);
    assert!(s.partition.sizes.iter().all(|&n| n >= min_size));
    // The minority material is a cluster of its own.
    let minority_label = s.partition.labels[300];
    let members = s
        .partition
        .labels
        .iter()
        .filter(|&&l| l == minority_label)
        .count();
    assert_eq!(members, 60, "{:?}", s.partition.sizes);
}
