//! A half-edge triangle mesh for a closed 2-manifold with the three local edits isotropic
//! remeshing needs: edge split, edge flip and edge collapse.
//!
//! Layout: face `f` owns half-edges `3f, 3f + 1, 3f + 2` in counter-clockwise order, so `next`
//! and `face` are arithmetic; stored per half-edge are its target vertex and its twin, per
//! vertex one outgoing half-edge. Deleted faces and vertices are marked and skipped; [`compact`]
//! rebuilds index arrays.
//!
//! Contract: [`HalfEdgeMesh::new`] accepts only closed, consistently oriented 2-manifolds
//! (every directed edge once, its reverse once). `flip` refuses when the new edge exists,
//! `collapse` when the link condition fails (the two end points share other neighbours than the
//! two opposite vertices) or an opposite vertex would drop to valence 3 — so every edit keeps
//! a closed 2-manifold.
//!
//! [`compact`]: HalfEdgeMesh::compact

use std::collections::HashMap;

use nalgebra::Vector3;

const NONE: u32 = u32::MAX;

/// The mesh.
#[derive(Clone, Debug)]
pub struct HalfEdgeMesh {
    /// Vertex positions.
    pub pos: Vec<Vector3<f64>>,
    to: Vec<u32>,
    twin: Vec<u32>,
    out: Vec<u32>,
    face_alive: Vec<bool>,
}

/// Why a triangle list is not a closed manifold.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum TopologyError {
    /// A directed edge appears twice (inconsistent orientation or a non-manifold edge).
    #[error("edge {0}→{1} is used twice")]
    DuplicateEdge(u32, u32),
    /// An edge has no opposite (a hole).
    #[error("edge {0}→{1} has no opposite edge (the surface is not closed)")]
    Open(u32, u32),
}

#[inline]
fn next(h: u32) -> u32 {
    if h % 3 == 2 { h - 2 } else { h + 1 }
}

#[inline]
fn prev(h: u32) -> u32 {
    if h % 3 == 0 { h + 2 } else { h - 1 }
}

impl HalfEdgeMesh {
    /// Builds the mesh (see the module contract).
    pub fn new(pos: Vec<Vector3<f64>>, triangles: &[[u32; 3]]) -> Result<Self, TopologyError> {
        let mut to = Vec::with_capacity(triangles.len() * 3);
        let mut index: HashMap<(u32, u32), u32> = HashMap::with_capacity(triangles.len() * 3);
        let mut out = vec![NONE; pos.len()];
        for (f, t) in triangles.iter().enumerate() {
            for e in 0..3 {
                let (a, b) = (t[e], t[(e + 1) % 3]);
                let h = (3 * f + e) as u32;
                if index.insert((a, b), h).is_some() {
                    return Err(TopologyError::DuplicateEdge(a, b));
                }
                to.push(b);
                out[a as usize] = h;
            }
        }
        let mut twin = vec![NONE; to.len()];
        for (&(a, b), &h) in &index {
            twin[h as usize] = *index.get(&(b, a)).ok_or(TopologyError::Open(a, b))?;
        }
        Ok(Self {
            pos,
            to,
            twin,
            out,
            face_alive: vec![true; triangles.len()],
        })
    }

    /// Source vertex of half-edge `h`.
    pub fn from(&self, h: u32) -> u32 {
        self.to[prev(h) as usize]
    }

    /// Target vertex of half-edge `h`.
    pub fn to(&self, h: u32) -> u32 {
        self.to[h as usize]
    }

    /// Its twin.
    pub fn twin(&self, h: u32) -> u32 {
        self.twin[h as usize]
    }

    /// Number of half-edge slots (live and dead).
    pub fn half_edges(&self) -> u32 {
        self.to.len() as u32
    }

    /// Whether half-edge `h`'s face is live.
    pub fn alive(&self, h: u32) -> bool {
        self.face_alive[(h / 3) as usize]
    }

    /// Whether vertex `v` is live.
    pub fn vertex_alive(&self, v: u32) -> bool {
        self.out[v as usize] != NONE
    }

    /// Outgoing half-edges of `v`, counter-clockwise.
    pub fn outgoing(&self, v: u32) -> Vec<u32> {
        let start = self.out[v as usize];
        let mut ring = Vec::with_capacity(8);
        if start == NONE {
            return ring;
        }
        let mut h = start;
        loop {
            ring.push(h);
            h = next(self.twin[h as usize]);
            // a closed manifold ring returns to its start; the bound guards corrupt input
            if h == start || ring.len() > 10_000 {
                return ring;
            }
        }
    }

    /// Neighbouring vertices of `v`.
    pub fn neighbours(&self, v: u32) -> Vec<u32> {
        self.outgoing(v).into_iter().map(|h| self.to(h)).collect()
    }

    /// Valence of `v`.
    pub fn valence(&self, v: u32) -> usize {
        self.outgoing(v).len()
    }

    /// Unit normal of the face of half-edge `h` (zero for a degenerate face).
    pub fn face_normal(&self, h: u32) -> Vector3<f64> {
        let f = h - h % 3;
        let [a, b, c] = [f, f + 1, f + 2].map(|x| self.pos[self.to(x) as usize]);
        (b - a)
            .cross(&(c - a))
            .try_normalize(0.0)
            .unwrap_or_default()
    }

    fn link(&mut self, a: u32, b: u32) {
        self.twin[a as usize] = b;
        self.twin[b as usize] = a;
    }

    /// Splits edge `h` at its midpoint; returns the new vertex.
    pub fn split(&mut self, h: u32) -> u32 {
        let t = self.twin(h);
        let (a, b) = (self.from(h), self.to(h));
        let c = self.to(next(h));
        let d = self.to(next(t));
        let (tw_bc, tw_ca) = (self.twin(next(h)), self.twin(prev(h)));
        let (tw_ad, tw_db) = (self.twin(next(t)), self.twin(prev(t)));
        let m = self.pos.len() as u32;
        self.pos
            .push((self.pos[a as usize] + self.pos[b as usize]) / 2.0);
        self.out.push(NONE);
        // face of h becomes (a, m, c); face of t becomes (b, m, d); new (m, b, c), (m, a, d)
        let f0 = h - h % 3;
        let f1 = t - t % 3;
        let f2 = self.to.len() as u32;
        let f3 = f2 + 3;
        self.to.extend_from_slice(&[b, c, m, a, d, m]);
        self.twin.extend_from_slice(&[NONE; 6]);
        self.face_alive.extend_from_slice(&[true, true]);
        self.to[f0 as usize..f0 as usize + 3].copy_from_slice(&[m, c, a]);
        self.to[f1 as usize..f1 as usize + 3].copy_from_slice(&[m, d, b]);
        // f0: a→m, m→c, c→a ; f2: m→b, b→c, c→m ; f1: b→m, m→d, d→b ; f3: m→a, a→d, d→m
        self.link(f0, f3); // a→m ↔ m→a
        self.link(f0 + 1, f2 + 2); // m→c ↔ c→m
        self.link(f0 + 2, tw_ca);
        self.link(f2, f1); // m→b ↔ b→m
        self.link(f2 + 1, tw_bc);
        self.link(f1 + 1, f3 + 2); // m→d ↔ d→m
        self.link(f1 + 2, tw_db);
        self.link(f3 + 1, tw_ad);
        self.out[m as usize] = f2;
        self.out[a as usize] = f0;
        self.out[b as usize] = f1;
        self.out[c as usize] = f0 + 2;
        self.out[d as usize] = f1 + 2;
        m
    }

    /// Flips edge `h` (a–b between faces (a, b, c) and (b, a, d)) to c–d; false if c–d exists.
    pub fn flip(&mut self, h: u32) -> bool {
        let t = self.twin(h);
        let (a, b) = (self.from(h), self.to(h));
        let c = self.to(next(h));
        let d = self.to(next(t));
        if c == d || self.neighbours(c).contains(&d) {
            return false;
        }
        let (tw_bc, tw_ca) = (self.twin(next(h)), self.twin(prev(h)));
        let (tw_ad, tw_db) = (self.twin(next(t)), self.twin(prev(t)));
        let f0 = h - h % 3;
        let f1 = t - t % 3;
        // f0: d→c, c→a, a→d ; f1: c→d, d→b, b→c
        self.to[f0 as usize..f0 as usize + 3].copy_from_slice(&[c, a, d]);
        self.to[f1 as usize..f1 as usize + 3].copy_from_slice(&[d, b, c]);
        self.link(f0, f1);
        self.link(f0 + 1, tw_ca);
        self.link(f0 + 2, tw_ad);
        self.link(f1 + 1, tw_db);
        self.link(f1 + 2, tw_bc);
        self.out[a as usize] = f0 + 2;
        self.out[b as usize] = f1 + 2;
        self.out[c as usize] = f0 + 1;
        self.out[d as usize] = f1 + 1;
        true
    }

    /// Whether collapsing `h` keeps a closed manifold (module contract).
    pub fn can_collapse(&self, h: u32) -> bool {
        let t = self.twin(h);
        let (a, b) = (self.from(h), self.to(h));
        let c = self.to(next(h));
        let d = self.to(next(t));
        if c == d || self.valence(c) <= 3 || self.valence(d) <= 3 {
            return false;
        }
        let nb = self.neighbours(b);
        self.neighbours(a)
            .iter()
            .filter(|v| nb.contains(v))
            .all(|&v| v == c || v == d)
    }

    /// Collapses `h` (a → b): a is removed, b moves to `position`. Call [`can_collapse`] first.
    ///
    /// [`can_collapse`]: HalfEdgeMesh::can_collapse
    pub fn collapse(&mut self, h: u32, position: Vector3<f64>) {
        let t = self.twin(h);
        let (a, b) = (self.from(h), self.to(h));
        let c = self.to(next(h));
        let d = self.to(next(t));
        let ring = self.outgoing(a);
        // every half-edge into a (outside the two dying faces) now ends at b
        for &o in &ring {
            let into = prev(o);
            if o / 3 != h / 3 && o / 3 != t / 3 {
                self.to[into as usize] = b;
            }
        }
        let (x, y) = (self.twin(next(h)), self.twin(prev(h))); // c→b, a→c (now b→c)
        let (p, q) = (self.twin(next(t)), self.twin(prev(t))); // d→a (now d→b), b→d
        self.link(x, y);
        self.link(p, q);
        self.face_alive[(h / 3) as usize] = false;
        self.face_alive[(t / 3) as usize] = false;
        self.out[a as usize] = NONE;
        self.out[b as usize] = q;
        self.out[c as usize] = x;
        self.out[d as usize] = p;
        self.pos[b as usize] = position;
    }

    /// Live vertices and triangles, renumbered.
    pub fn compact(&self) -> (Vec<Vector3<f64>>, Vec<[u32; 3]>) {
        let mut map = vec![NONE; self.pos.len()];
        let mut pos = Vec::new();
        for (v, p) in self.pos.iter().enumerate() {
            if self.out[v] != NONE {
                map[v] = pos.len() as u32;
                pos.push(*p);
            }
        }
        let triangles = (0..self.face_alive.len())
            .filter(|&f| self.face_alive[f])
            .map(|f| std::array::from_fn(|e| map[self.to[3 * f + e] as usize]))
            .collect();
        (pos, triangles)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_model::geometry::procedural::icosphere;

    fn sphere() -> HalfEdgeMesh {
        let (dirs, tris) = icosphere(2);
        HalfEdgeMesh::new(dirs.iter().map(|d| d.into_inner()).collect(), &tris).unwrap()
    }

    fn check(m: &HalfEdgeMesh) {
        let (pos, tris) = m.compact();
        let again = HalfEdgeMesh::new(pos.clone(), &tris).expect("closed manifold");
        assert_eq!(
            pos.len() as i64 - tris.len() as i64 / 2,
            2,
            "Euler characteristic"
        );
        drop(again);
    }

    #[test]
    fn split_flip_and_collapse_keep_a_closed_sphere() {
        let mut m = sphere();
        let v0 = m.pos.len();
        m.split(0);
        check(&m);
        assert_eq!(m.pos.len(), v0 + 1);
        let h = m.out[3];
        assert!(m.flip(h) || !m.alive(h));
        check(&m);
        let mut collapsed = 0;
        for h in 0..m.half_edges() {
            if m.alive(h) && m.vertex_alive(m.from(h)) && m.can_collapse(h) {
                let p = m.pos[m.to(h) as usize];
                m.collapse(h, p);
                collapsed += 1;
                check(&m);
                if collapsed == 20 {
                    break;
                }
            }
        }
        assert_eq!(collapsed, 20);
    }

    #[test]
    fn open_meshes_are_refused() {
        let (dirs, mut tris) = icosphere(1);
        tris.pop();
        let e = HalfEdgeMesh::new(dirs.iter().map(|d| d.into_inner()).collect(), &tris);
        assert!(matches!(e, Err(TopologyError::Open(..))));
    }
}
