//! A compact bounding-volume hierarchy built with the binned surface-area heuristic (SAH).
//!
//! Contract: [`Bvh::build`] takes one bounding box per primitive and never fails (empty input
//! gives an empty tree that nothing hits). [`Bvh::traverse`] visits, front to back by box entry
//! distance, every leaf whose box the ray enters within `[t_min, t_max]`, calls the caller's
//! primitive test, and shrinks `t_max` to each reported hit, so the result is the same nearest hit a
//! brute-force loop over all primitives finds (tested against that loop on random meshes).
//!
//! Layout: nodes in one `Vec`; an inner node's children are adjacent (`first`, `first + 1`); a leaf
//! owns `indices[first .. first + count]`. Depth is capped at [`MAX_DEPTH`] (a deeper subtree becomes
//! one leaf), which bounds the fixed traversal stack.

use super::{Aabb, Ray};
use nalgebra::{Point3, Vector3};

/// Bins per axis for the SAH sweep.
const BINS: usize = 16;
/// Leaves are not split below this many primitives.
const MIN_SPLIT: usize = 3;
/// Largest leaf the builder accepts when no split beats the leaf cost.
const MAX_LEAF: usize = 16;
/// Depth cap; keeps the traversal stack bounded.
pub const MAX_DEPTH: usize = 48;
/// SAH cost of one traversal step relative to one primitive test.
const TRAVERSAL_COST: f64 = 1.0;

#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: Aabb,
    /// Leaf: start in `indices`. Inner: index of the left child (right = left + 1).
    first: u32,
    /// Number of primitives; 0 for inner nodes.
    count: u32,
}

/// A bounding-volume hierarchy over primitives identified by `u32` indices.
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    nodes: Vec<Node>,
    indices: Vec<u32>,
}

struct Build {
    node: usize,
    start: usize,
    end: usize,
    depth: usize,
}

impl Bvh {
    /// Builds the hierarchy over `prim_bounds[i]` for primitive `i`.
    pub fn build(prim_bounds: &[Aabb]) -> Self {
        let n = prim_bounds.len();
        let mut indices: Vec<u32> = (0..n as u32).collect();
        if n == 0 {
            return Self {
                nodes: Vec::new(),
                indices,
            };
        }
        let centroids: Vec<Point3<f64>> = prim_bounds.iter().map(Aabb::centre).collect();
        let mut nodes = vec![Node {
            bounds: Aabb::empty(),
            first: 0,
            count: 0,
        }];
        let mut stack = vec![Build {
            node: 0,
            start: 0,
            end: n,
            depth: 0,
        }];
        while let Some(job) = stack.pop() {
            let items = &mut indices[job.start..job.end];
            let bounds = items
                .iter()
                .fold(Aabb::empty(), |b, &i| b.union(&prim_bounds[i as usize]));
            let centroid_bounds = Aabb::from_points(items.iter().map(|&i| &centroids[i as usize]));
            nodes[job.node].bounds = bounds;
            let count = items.len();
            let split = if count < MIN_SPLIT || job.depth >= MAX_DEPTH {
                None
            } else {
                best_split(items, prim_bounds, &centroids, &centroid_bounds, &bounds)
            };
            let mid = match split {
                Some((axis, pos, cost)) if cost < count as f64 || count > MAX_LEAF => {
                    partition(items, |&i| centroids[i as usize][axis] < pos)
                }
                _ => 0,
            };
            if mid == 0 || mid == count {
                nodes[job.node].first = job.start as u32;
                nodes[job.node].count = count as u32;
                continue;
            }
            let left = nodes.len();
            nodes.push(Node {
                bounds: Aabb::empty(),
                first: 0,
                count: 0,
            });
            nodes.push(Node {
                bounds: Aabb::empty(),
                first: 0,
                count: 0,
            });
            nodes[job.node].first = left as u32;
            let depth = job.depth + 1;
            stack.push(Build {
                node: left,
                start: job.start,
                end: job.start + mid,
                depth,
            });
            stack.push(Build {
                node: left + 1,
                start: job.start + mid,
                end: job.end,
                depth,
            });
        }
        Self { nodes, indices }
    }

    /// Bounds of everything (empty for an empty tree).
    pub fn bounds(&self) -> Aabb {
        self.nodes.first().map_or_else(Aabb::empty, |n| n.bounds)
    }

    /// Number of nodes (for statistics and tests).
    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// Visits candidate primitives front to back. `test(prim, t_max)` returns the primitive's hit
    /// distance if it is hit with `t_min < t < t_max`. With `any_hit` the walk stops at the first
    /// reported hit (shadow rays). Returns the nearest reported `(prim, t)`.
    pub fn traverse(
        &self,
        ray: &Ray,
        t_min: f64,
        t_max: f64,
        any_hit: bool,
        mut test: impl FnMut(u32, f64) -> Option<f64>,
    ) -> Option<(u32, f64)> {
        if self.nodes.is_empty() {
            return None;
        }
        let inv_dir: Vector3<f64> = ray.dir.map(|d| 1.0 / d);
        let finite = inv_dir.iter().all(|v| v.is_finite());
        let slab = |b: &Aabb, t_max: f64| {
            if finite {
                b.slab_finite(&ray.origin, &inv_dir, t_min, t_max)
            } else {
                b.slab(&ray.origin, &inv_dir, t_min, t_max)
            }
        };
        let mut best: Option<(u32, f64)> = None;
        let mut t_best = t_max;
        let mut stack = [0u32; MAX_DEPTH + 2];
        let mut top = 0usize;
        slab(&self.nodes[0].bounds, t_best)?;
        let mut current = 0usize;
        loop {
            let node = &self.nodes[current];
            if node.count > 0 {
                let start = node.first as usize;
                for &prim in &self.indices[start..start + node.count as usize] {
                    if let Some(t) = test(prim, t_best) {
                        if t < t_best && t > t_min {
                            t_best = t;
                            best = Some((prim, t));
                            if any_hit {
                                return best;
                            }
                        }
                    }
                }
            } else {
                let left = node.first as usize;
                let tl = slab(&self.nodes[left].bounds, t_best);
                let tr = slab(&self.nodes[left + 1].bounds, t_best);
                match (tl, tr) {
                    (Some(a), Some(b)) => {
                        let (near, far) = if a <= b {
                            (left, left + 1)
                        } else {
                            (left + 1, left)
                        };
                        stack[top] = far as u32;
                        top += 1;
                        current = near;
                        continue;
                    }
                    (Some(_), None) => {
                        current = left;
                        continue;
                    }
                    (None, Some(_)) => {
                        current = left + 1;
                        continue;
                    }
                    (None, None) => {}
                }
            }
            // Pop the next pending subtree that the ray can still reach before `t_best`.
            loop {
                if top == 0 {
                    return best;
                }
                top -= 1;
                let cand = stack[top] as usize;
                if slab(&self.nodes[cand].bounds, t_best).is_some() {
                    current = cand;
                    break;
                }
            }
        }
    }
}

impl Bvh {
    /// The primitive nearest to `point`: `distance(prim, best)` returns the primitive's distance
    /// to `point` (it may return any value ≥ `best` once it knows it cannot win). Boxes are
    /// visited nearer child first and skipped once their distance reaches the best so far, so
    /// the result is the minimum over all primitives (tested against a brute-force loop). `None`
    /// for an empty tree.
    pub fn nearest(
        &self,
        point: &Point3<f64>,
        mut distance: impl FnMut(u32, f64) -> f64,
    ) -> Option<(u32, f64)> {
        let first = self.nodes.first()?;
        let mut best: Option<(u32, f64)> = None;
        let mut d_best = f64::INFINITY;
        let mut stack = [(0u32, 0.0f64); MAX_DEPTH + 2];
        stack[0] = (0, box_distance(&first.bounds, point));
        let mut top = 1usize;
        while top > 0 {
            top -= 1;
            let (current, d_box) = stack[top];
            if d_box >= d_best {
                continue;
            }
            let node = &self.nodes[current as usize];
            if node.count > 0 {
                let start = node.first as usize;
                for &prim in &self.indices[start..start + node.count as usize] {
                    let d = distance(prim, d_best);
                    if d < d_best {
                        d_best = d;
                        best = Some((prim, d));
                    }
                }
            } else {
                let left = node.first;
                let dl = box_distance(&self.nodes[left as usize].bounds, point);
                let dr = box_distance(&self.nodes[left as usize + 1].bounds, point);
                // push the farther child first so the nearer one is visited next
                let (near, far) = if dl <= dr {
                    ((left, dl), (left + 1, dr))
                } else {
                    ((left + 1, dr), (left, dl))
                };
                stack[top] = far;
                stack[top + 1] = near;
                top += 2;
            }
        }
        best
    }
}

/// Euclidean distance from `p` to the box (0 inside).
fn box_distance(b: &Aabb, p: &Point3<f64>) -> f64 {
    let d = Vector3::from_fn(|a, _| (b.min[a] - p[a]).max(p[a] - b.max[a]).max(0.0));
    d.norm()
}

/// Best binned SAH split: `(axis, centroid threshold, cost in primitive-test units)`.
fn best_split(
    items: &[u32],
    prim_bounds: &[Aabb],
    centroids: &[Point3<f64>],
    centroid_bounds: &Aabb,
    bounds: &Aabb,
) -> Option<(usize, f64, f64)> {
    let parent_area = bounds.surface_area();
    let mut best: Option<(usize, f64, f64)> = None;
    #[expect(
        clippy::needless_range_loop,
        reason = "axis indexes points and boxes alike"
    )]
    for axis in 0..3 {
        let lo = centroid_bounds.min[axis];
        let hi = centroid_bounds.max[axis];
        let extent = hi - lo;
        // A flat centroid spread on this axis cannot separate anything.
        if extent.is_nan() || extent <= 1e-300 {
            continue;
        }
        let mut bin_bounds = [Aabb::empty(); BINS];
        let mut bin_count = [0usize; BINS];
        let scale = BINS as f64 / extent;
        let bin_of = |c: f64| (((c - lo) * scale) as usize).min(BINS - 1);
        for &i in items {
            let b = bin_of(centroids[i as usize][axis]);
            bin_count[b] += 1;
            bin_bounds[b].grow(&prim_bounds[i as usize]);
        }
        // Sweep: right-side accumulations, then left side with costs.
        let mut right_area = [0.0; BINS];
        let mut right_count = [0usize; BINS];
        let mut acc = Aabb::empty();
        let mut cnt = 0;
        for b in (1..BINS).rev() {
            acc.grow(&bin_bounds[b]);
            cnt += bin_count[b];
            right_area[b] = acc.surface_area();
            right_count[b] = cnt;
        }
        let mut acc = Aabb::empty();
        let mut cnt = 0;
        for b in 0..BINS - 1 {
            acc.grow(&bin_bounds[b]);
            cnt += bin_count[b];
            let (nl, nr) = (cnt, right_count[b + 1]);
            if nl == 0 || nr == 0 {
                continue;
            }
            // Guard: a degenerate (zero-area) parent makes every split cost its primitive count.
            let cost = if parent_area > 0.0 {
                TRAVERSAL_COST
                    + (acc.surface_area() * nl as f64 + right_area[b + 1] * nr as f64) / parent_area
            } else {
                TRAVERSAL_COST + (nl.max(nr)) as f64
            };
            if best.is_none_or(|(_, _, c)| cost < c) {
                best = Some((axis, lo + (b + 1) as f64 / scale, cost));
            }
        }
    }
    best
}

/// In-place partition; returns the number of items satisfying `pred` (moved to the front).
fn partition(items: &mut [u32], pred: impl Fn(&u32) -> bool) -> usize {
    let mut mid = 0;
    for i in 0..items.len() {
        if pred(&items[i]) {
            items.swap(i, mid);
            mid += 1;
        }
    }
    mid
}

#[cfg(test)]
mod tests {
    use super::*;

    fn boxes_on_a_line(n: usize) -> Vec<Aabb> {
        (0..n)
            .map(|i| {
                let x = i as f64;
                Aabb {
                    min: Point3::new(x, 0.0, 0.0),
                    max: Point3::new(x + 0.5, 1.0, 1.0),
                }
            })
            .collect()
    }

    #[test]
    fn every_primitive_lands_in_exactly_one_leaf() {
        let bvh = Bvh::build(&boxes_on_a_line(1000));
        let mut seen = vec![0u32; 1000];
        for node in &bvh.nodes {
            if node.count > 0 {
                for &i in &bvh.indices[node.first as usize..(node.first + node.count) as usize] {
                    seen[i as usize] += 1;
                }
            }
        }
        assert!(seen.iter().all(|&c| c == 1));
        assert!(bvh.node_count() > 100, "1000 separated boxes must be split");
    }

    #[test]
    fn identical_centroids_make_one_leaf() {
        let b = Aabb {
            min: Point3::origin(),
            max: Point3::new(1.0, 1.0, 1.0),
        };
        let bvh = Bvh::build(&vec![b; 50]);
        assert_eq!(bvh.node_count(), 1);
    }

    #[test]
    fn nearest_agrees_with_a_brute_force_loop() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let boxes: Vec<Aabb> = (0..500)
            .map(|_| {
                let c = Point3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                );
                let h = Vector3::repeat(rng.random_range(0.001..0.05));
                Aabb {
                    min: c - h,
                    max: c + h,
                }
            })
            .collect();
        let bvh = Bvh::build(&boxes);
        for _ in 0..200 {
            let p = Point3::new(
                rng.random_range(-3.0..3.0),
                rng.random_range(-3.0..3.0),
                rng.random_range(-3.0..3.0),
            );
            let brute = boxes
                .iter()
                .map(|b| box_distance(b, &p))
                .fold(f64::INFINITY, f64::min);
            let (prim, d) = bvh
                .nearest(&p, |i, _| box_distance(&boxes[i as usize], &p))
                .expect("non-empty");
            assert_eq!(d, brute);
            assert_eq!(box_distance(&boxes[prim as usize], &p), brute);
        }
        assert!(
            Bvh::build(&[])
                .nearest(&Point3::origin(), |_, _| 0.0)
                .is_none()
        );
    }

    #[test]
    fn traversal_finds_nearest_box_front_to_back() {
        let boxes = boxes_on_a_line(64);
        let bvh = Bvh::build(&boxes);
        let ray = Ray::new(Point3::new(-10.0, 0.5, 0.5), Vector3::new(1.0, 0.0, 0.0));
        let inv = ray.dir.map(|d| 1.0 / d);
        let mut tests = 0;
        let hit = bvh.traverse(&ray, 0.0, f64::INFINITY, false, |p, t_max| {
            tests += 1;
            boxes[p as usize].slab(&ray.origin, &inv, 0.0, t_max)
        });
        assert_eq!(hit.map(|h| h.0), Some(0));
        assert!(
            tests < 64,
            "front-to-back traversal must prune: {tests} tests"
        );
        let empty = Bvh::build(&[]);
        assert!(
            empty
                .traverse(&ray, 0.0, 1.0, false, |_, _| Some(0.5))
                .is_none()
        );
    }
}
