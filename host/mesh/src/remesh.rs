//! Isotropic remeshing to a target vertex count, onto an implicit surface, then light
//! smoothing.
//!
//! Method (Botsch & Kobbelt, "A Remeshing Approach to Multiresolution Modeling", SGP 2004): for
//! a target edge length L, repeat: split edges longer than 4/3 L; collapse edges shorter than
//! 4/5 L (to their midpoint, refused where it would make an edge longer than 4/3 L or turn a
//! face by more than 60°); flip edges where that brings the four vertices' valences closer to
//! 6; move every vertex toward the centroid of its neighbours within its tangent plane; project
//! every vertex back onto the surface. L is chosen from the surface area so a closed mesh of
//! equilateral triangles would have the target vertex count (A = 2N · √3/4 · L²).
//!
//! Taubin smoothing (λ|μ, "A Signal Processing Approach to Fair Surface Design", SIGGRAPH 1995)
//! then removes pixel-scale ripple of the carved surface without the shrinkage of plain
//! Laplacian smoothing.
//!
//! Contract: input and output are closed 2-manifolds (every edit keeps one, see `halfedge`);
//! the vertex count lands near the target (measured within a few percent, docs/mesh.md).

use nalgebra::{Matrix3, Vector3};

use super::halfedge::HalfEdgeMesh;

/// Settings of the remeshing.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RemeshConfig {
    /// Target vertex count.
    pub target_vertices: usize,
    /// Split–collapse–flip–relax–project rounds.
    pub iterations: usize,
    /// Taubin λ|μ pairs after the last round.
    pub smoothing_steps: usize,
}

impl Default for RemeshConfig {
    fn default() -> Self {
        Self {
            target_vertices: 2500,
            iterations: 8,
            smoothing_steps: 3,
        }
    }
}

/// Surface area of the live faces.
pub fn area(mesh: &HalfEdgeMesh) -> f64 {
    (0..mesh.half_edges())
        .step_by(3)
        .filter(|&h| mesh.alive(h))
        .map(|h| {
            let [a, b, c] = [h, h + 1, h + 2].map(|x| mesh.pos[mesh.to(x) as usize]);
            0.5 * (b - a).cross(&(c - a)).norm()
        })
        .sum()
}

/// The edge length that gives `vertices` vertices on a closed surface of area `area`.
pub fn target_edge(area: f64, vertices: usize) -> f64 {
    (2.0 * area / (3f64.sqrt() * vertices.max(4) as f64)).sqrt()
}

fn edge_length(m: &HalfEdgeMesh, h: u32) -> f64 {
    (m.pos[m.to(h) as usize] - m.pos[m.from(h) as usize]).norm()
}

fn split_long(m: &mut HalfEdgeMesh, high: f64, project: &dyn Fn(Vector3<f64>) -> Vector3<f64>) {
    for _ in 0..8 {
        let mut any = false;
        let n = m.half_edges();
        for h in 0..n {
            if m.alive(h) && h < m.twin(h) && edge_length(m, h) > high {
                let v = m.split(h) as usize;
                m.pos[v] = project(m.pos[v]);
                any = true;
            }
        }
        if !any {
            return;
        }
    }
}

/// Faces around `a` and `b` (excluding those of edge `h`) keep their orientation and no edge
/// longer than `high` appears when both move to `p`.
fn collapse_is_safe(m: &HalfEdgeMesh, h: u32, p: Vector3<f64>, high: f64) -> bool {
    let t = m.twin(h);
    let (a, b) = (m.from(h), m.to(h));
    for v in [a, b] {
        for o in m.outgoing(v) {
            if o / 3 == h / 3 || o / 3 == t / 3 {
                continue;
            }
            let f = o - o % 3;
            let corners = [f, f + 1, f + 2].map(|x| m.to(x));
            let old = corners.map(|c| m.pos[c as usize]);
            let new = corners.map(|c| {
                if c == a || c == b {
                    p
                } else {
                    m.pos[c as usize]
                }
            });
            let n_old = (old[1] - old[0]).cross(&(old[2] - old[0]));
            let n_new = (new[1] - new[0]).cross(&(new[2] - new[0]));
            // cos 60° = 0.5 between the face's old and new normal
            if n_new.dot(&n_old) <= 0.5 * n_old.norm() * n_new.norm() {
                return false;
            }
            if (0..3).any(|e| (new[(e + 1) % 3] - new[e]).norm() > high) {
                return false;
            }
        }
    }
    true
}

fn collapse_short(
    m: &mut HalfEdgeMesh,
    low: f64,
    high: f64,
    project: &dyn Fn(Vector3<f64>) -> Vector3<f64>,
) {
    for _ in 0..8 {
        let mut any = false;
        for h in 0..m.half_edges() {
            if !m.alive(h) || edge_length(m, h) >= low || !m.can_collapse(h) {
                continue;
            }
            let p = project((m.pos[m.from(h) as usize] + m.pos[m.to(h) as usize]) / 2.0);
            if collapse_is_safe(m, h, p, high) {
                m.collapse(h, p);
                any = true;
            }
        }
        if !any {
            return;
        }
    }
}

fn flip_to_valence_six(m: &mut HalfEdgeMesh) {
    for h in 0..m.half_edges() {
        if !m.alive(h) || h > m.twin(h) {
            continue;
        }
        let t = m.twin(h);
        let (a, b) = (m.from(h), m.to(h));
        let c = m.to(next_of(h));
        let d = m.to(next_of(t));
        let dev = |v: u32, delta: isize| (m.valence(v) as isize + delta - 6).pow(2);
        let before = dev(a, 0) + dev(b, 0) + dev(c, 0) + dev(d, 0);
        let after = dev(a, -1) + dev(b, -1) + dev(c, 1) + dev(d, 1);
        if after >= before || m.valence(a) <= 3 || m.valence(b) <= 3 {
            continue;
        }
        // keep the surface: the two new faces must face the way the old ones did
        let [pa, pb, pc, pd] = [a, b, c, d].map(|v| m.pos[v as usize]);
        let n_old = (pb - pa).cross(&(pc - pa)) + (pa - pb).cross(&(pd - pb));
        let n1 = (pa - pc).cross(&(pd - pc));
        let n2 = (pb - pd).cross(&(pc - pd));
        if n1.dot(&n_old) <= 0.0 || n2.dot(&n_old) <= 0.0 || n1.dot(&n2) <= 0.0 {
            continue;
        }
        m.flip(h);
    }
}

fn next_of(h: u32) -> u32 {
    if h % 3 == 2 { h - 2 } else { h + 1 }
}

/// Area-weighted vertex normals (zero for dead vertices).
pub fn vertex_normals(m: &HalfEdgeMesh) -> Vec<Vector3<f64>> {
    let mut normals = vec![Vector3::zeros(); m.pos.len()];
    for h in (0..m.half_edges()).step_by(3) {
        if !m.alive(h) {
            continue;
        }
        let vs = [h, h + 1, h + 2].map(|x| m.to(x) as usize);
        let [a, b, c] = vs.map(|v| m.pos[v]);
        let n = (b - a).cross(&(c - a));
        for v in vs {
            normals[v] += n;
        }
    }
    normals
        .into_iter()
        .map(|n| n.try_normalize(0.0).unwrap_or_default())
        .collect()
}

fn relax_tangentially(m: &mut HalfEdgeMesh) {
    let normals = vertex_normals(m);
    let moved: Vec<Option<Vector3<f64>>> = (0..m.pos.len() as u32)
        .map(|v| {
            if !m.vertex_alive(v) {
                return None;
            }
            let ring = m.neighbours(v);
            let centroid = ring
                .iter()
                .map(|&u| m.pos[u as usize])
                .sum::<Vector3<f64>>()
                / ring.len() as f64;
            let n = normals[v as usize];
            let tangent = Matrix3::identity() - n * n.transpose();
            Some(m.pos[v as usize] + tangent * (centroid - m.pos[v as usize]))
        })
        .collect();
    for (p, q) in m.pos.iter_mut().zip(moved) {
        if let Some(q) = q {
            *p = q;
        }
    }
}

/// One Laplacian step with weight `lambda` (uniform weights).
fn laplacian_step(m: &mut HalfEdgeMesh, lambda: f64) {
    let moved: Vec<Option<Vector3<f64>>> = (0..m.pos.len() as u32)
        .map(|v| {
            if !m.vertex_alive(v) {
                return None;
            }
            let ring = m.neighbours(v);
            let centroid = ring
                .iter()
                .map(|&u| m.pos[u as usize])
                .sum::<Vector3<f64>>()
                / ring.len() as f64;
            Some(m.pos[v as usize] + lambda * (centroid - m.pos[v as usize]))
        })
        .collect();
    for (p, q) in m.pos.iter_mut().zip(moved) {
        if let Some(q) = q {
            *p = q;
        }
    }
}

/// Remeshes `m` (see the module doc); `project` maps a point onto the surface.
pub fn remesh(
    mut m: HalfEdgeMesh,
    config: &RemeshConfig,
    project: &dyn Fn(Vector3<f64>) -> Vector3<f64>,
) -> HalfEdgeMesh {
    for _ in 0..config.iterations.max(1) {
        // recomputed each round: the area converges as the mesh leaves the grid's staircase
        let l = target_edge(area(&m), config.target_vertices);
        let (low, high) = (0.8 * l, 4.0 / 3.0 * l);
        split_long(&mut m, high, project);
        collapse_short(&mut m, low, high, project);
        flip_to_valence_six(&mut m);
        relax_tangentially(&mut m);
        for p in m.pos.iter_mut() {
            *p = project(*p);
        }
    }
    for _ in 0..config.smoothing_steps {
        laplacian_step(&mut m, 0.5);
        laplacian_step(&mut m, -0.53);
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_model::geometry::procedural::icosphere;

    #[test]
    fn a_fine_sphere_is_remeshed_to_the_target_count_and_stays_on_the_sphere() {
        let (dirs, tris) = icosphere(5); // 10 242 vertices
        let m = HalfEdgeMesh::new(dirs.iter().map(|d| d.into_inner()).collect(), &tris).unwrap();
        let config = RemeshConfig {
            target_vertices: 800,
            iterations: 6,
            smoothing_steps: 0,
        };
        let out = remesh(m, &config, &|p: Vector3<f64>| p.normalize());
        let (pos, tris) = out.compact();
        let again = HalfEdgeMesh::new(pos.clone(), &tris).expect("closed manifold");
        assert!(
            (pos.len() as f64 / 800.0 - 1.0).abs() < 0.15,
            "{} vertices",
            pos.len()
        );
        // triangle quality: most angles away from slivers
        let mut worst = f64::INFINITY;
        for t in &tris {
            let [a, b, c] = t.map(|i| pos[i as usize]);
            for (p, q, r) in [(a, b, c), (b, c, a), (c, a, b)] {
                let angle = (q - p).angle(&(r - p)).to_degrees();
                worst = worst.min(angle);
            }
        }
        assert!(worst > 15.0, "smallest angle {worst}°");
        assert!(again.pos.iter().all(|p| (p.norm() - 1.0).abs() < 1e-9));
    }
}
