//! Mesh neighbourhoods for the steps that look at a vertex's surroundings: each vertex's edge
//! neighbours (its 1-ring) with the edge lengths, the vertices within k rings, and edge-length
//! graph distances from a set of vertices.
//!
//! Contract: built from a mesh's triangles, so every vertex of the mesh has an entry (an
//! isolated vertex an empty one); neighbours are listed once, in first-seen order, so every
//! result is deterministic.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use ellipso_model::geometry::TriangleMesh;

/// Every vertex's edge neighbours with the edge lengths, metres.
pub fn adjacency(mesh: &TriangleMesh) -> Vec<Vec<(u32, f64)>> {
    let p = mesh.positions();
    let mut adj: Vec<Vec<(u32, f64)>> = vec![Vec::new(); p.len()];
    for t in mesh.triangles() {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let len = (p[a as usize] - p[b as usize]).norm();
            for (x, y) in [(a, b), (b, a)] {
                let list = &mut adj[x as usize];
                if !list.iter().any(|(z, _)| *z == y) {
                    list.push((y, len));
                }
            }
        }
    }
    adj
}

/// Every vertex's edge neighbours (its 1-ring), without lengths.
pub fn rings(mesh: &TriangleMesh) -> Vec<Vec<u32>> {
    adjacency(mesh)
        .into_iter()
        .map(|l| l.into_iter().map(|(v, _)| v).collect())
        .collect()
}

/// The vertices within `k` rings of `v` in `rings` (`v` first, then ring by ring).
pub fn within(rings: &[Vec<u32>], v: usize, k: usize) -> Vec<usize> {
    let mut out = vec![v];
    let mut frontier = vec![v];
    for _ in 0..k {
        let mut next = Vec::new();
        for &u in &frontier {
            for &w in rings.get(u).map_or(&[][..], Vec::as_slice) {
                let w = w as usize;
                if !out.contains(&w) {
                    out.push(w);
                    next.push(w);
                }
            }
        }
        frontier = next;
    }
    out
}

/// Edge-length graph distances from every vertex to the nearest vertex of `sources`
/// (multi-source Dijkstra); `f64::INFINITY` where none is reachable.
pub fn graph_distance(adjacency: &[Vec<(u32, f64)>], sources: &[usize]) -> Vec<f64> {
    let mut dist = vec![f64::INFINITY; adjacency.len()];
    let mut heap = BinaryHeap::new();
    for &s in sources {
        dist[s] = 0.0;
        heap.push(Reverse((0.0f64.to_bits(), s)));
    }
    // A non-negative finite f64's bits order as the number does.
    while let Some(Reverse((d, v))) = heap.pop() {
        let d = f64::from_bits(d);
        if d > dist[v] {
            continue;
        }
        for &(w, len) in &adjacency[v] {
            let w = w as usize;
            let nd = d + len;
            if nd < dist[w] {
                dist[w] = nd;
                heap.push(Reverse((nd.to_bits(), w)));
            }
        }
    }
    dist
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_model::geometry::procedural::icosphere;
    use nalgebra::Point3;

    #[test]
    fn rings_distances_and_neighbourhoods_of_an_icosphere() {
        let (dirs, faces) = icosphere(1);
        let pos = dirs.iter().map(|d| Point3::from(d.into_inner())).collect();
        let mesh = TriangleMesh::new(pos, None, None, faces).unwrap();
        let r = rings(&mesh);
        // An icosphere's vertices have 5 or 6 neighbours.
        assert!(r.iter().all(|l| l.len() == 5 || l.len() == 6));
        let one = within(&r, 0, 1);
        assert_eq!(one.len(), 1 + r[0].len());
        assert!(within(&r, 0, 2).len() > one.len());
        let adj = adjacency(&mesh);
        let d = graph_distance(&adj, &[0]);
        assert_eq!(d[0], 0.0);
        for &(w, len) in &adj[0] {
            assert!((d[w as usize] - len).abs() < 1e-12);
        }
        // Every vertex is reachable on a closed sphere, none farther than half a great circle
        // measured along edges (a little longer than π).
        assert!(d.iter().all(|x| x.is_finite() && *x < 4.0));
    }
}
