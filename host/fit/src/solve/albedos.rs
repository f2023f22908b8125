//! The linear unknowns of one vertex — ρ_d and ρ_ss per colour channel and the shared ρ_s — by
//! exact box-constrained least squares (variable projection, docs/fit-solver.md "Bounds").
//!
//! Contract:
//! - Observations are linear in the albedos (docs/model.md §11 "Unknowns"), so for fixed
//!   nonlinear unknowns the loss is a convex quadratic Q(β_1…β_C, ρ_s) = Σ_c [½β_cᵀH_cβ_c +
//!   ρ_s·h_cᵀβ_c − g_cᵀβ_c] + ½h_ss·ρ_s² − g_s·ρ_s, with β_c = (ρ_d,c, ρ_ss,c) and every
//!   albedo in [0, cap]. [`AlbedoSystem`] accumulates H, h, g from weighted residual rows.
//! - [`AlbedoSystem::solve`] returns the exact minimiser over the box. The channels couple only
//!   through ρ_s, so Q reduced over the β's is a convex piecewise-quadratic function φ(ρ_s) whose
//!   derivative φ′ = h_ss·ρ_s − g_s + Σ_c h_cᵀβ_c*(ρ_s) is monotone and piecewise linear (the
//!   envelope theorem); its root is found on [0, cap] by Newton steps between the pieces inside a
//!   shrinking bracket, each piece's root exact. For fixed ρ_s each channel's 2×2 box problem is
//!   solved by enumerating the faces of the square ([`Face`]).
//! - The solution is evaluated in the caller's scalar type with the active faces fixed, so in
//!   dual arithmetic the albedos carry their exact derivatives with respect to the nonlinear
//!   unknowns (the Jacobian of the projected problem). Values on a bound are constants.
//! - A variable whose quadratic term is zero (a lobe that predicts nothing) stays at 0.

use ellipso_model::optics::Real;

/// The linear albedos of one vertex (ρ_d and ρ_ss per colour channel, ρ_s shared).
#[derive(Clone, Copy, Debug)]
pub(super) struct Albedos<T> {
    pub rho_d: [T; 3],
    pub rho_ss: [T; 3],
    pub rho_s: T,
}

/// Normal equations of the albedo least squares (module doc), per colour channel c:
/// `h[c]` = (H_aa, H_ab, H_bb) over (ρ_d,c, ρ_ss,c), `hs[c]` their coupling to ρ_s, `g[c]`
/// the right-hand side; `hss`, `gs` those of ρ_s.
pub(super) struct AlbedoSystem<T> {
    h: [[T; 3]; 3],
    hs: [[T; 2]; 3],
    g: [[T; 2]; 3],
    hss: T,
    gs: T,
}

/// Which face of the square [0, cap]² a channel's (ρ_d, ρ_ss) lies on.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Face {
    /// Both inside.
    Free,
    /// ρ_d inside, ρ_ss at the given bound.
    DFree(f64),
    /// ρ_ss inside, ρ_d at the given bound.
    SsFree(f64),
    /// Both at bounds.
    Corner(f64, f64),
}

impl<T: Real> AlbedoSystem<T> {
    pub fn new() -> Self {
        let z = T::zero();
        Self {
            h: [[z; 3]; 3],
            hs: [[z; 2]; 3],
            g: [[z; 2]; 3],
            hss: z,
            gs: z,
        }
    }

    /// Adds the residual row `√w·(ρ_d·a + ρ_ss·b + ρ_s·s − o)` of colour channel `c`.
    #[inline]
    pub fn add_row(&mut self, c: usize, w: T, a: T, b: T, s: T, o: T) {
        let (wa, wb, ws) = (w * a, w * b, w * s);
        let h = &mut self.h[c];
        h[0] += wa * a;
        h[1] += wa * b;
        h[2] += wb * b;
        self.hs[c][0] += wa * s;
        self.hs[c][1] += wb * s;
        self.g[c][0] += wa * o;
        self.g[c][1] += wb * o;
        self.hss += ws * s;
        self.gs += ws * o;
    }

    /// Adds the row `√w·(ρ_ss·b + ρ_s·s − o)` of channel `c` (a virtual sample: no diffuse).
    #[inline]
    pub fn add_specular_row(&mut self, c: usize, w: T, b: T, s: T, o: T) {
        let wb = w * b;
        self.h[c][2] += wb * b;
        self.hs[c][1] += wb * s;
        self.g[c][1] += wb * o;
        let ws = w * s;
        self.hss += ws * s;
        self.gs += ws * o;
    }

    /// The exact minimiser over [0, `cap`]^(2·channels + 1) (module doc); channels beyond
    /// `channels` copy the last one.
    pub fn solve(&self, channels: usize, cap: f64) -> Albedos<T> {
        self.solve_faces(channels, cap).0
    }

    /// [`AlbedoSystem::solve`] and which albedos are free on the minimiser's face (strictly
    /// inside the box, determined by the face's linear equations), in the layout ρ_d,c = c,
    /// ρ_ss,c = 3 + c, ρ_s = 6 (channels beyond `channels` are copies, never free).
    pub fn solve_faces(&self, channels: usize, cap: f64) -> (Albedos<T>, [bool; 7]) {
        let channels = channels.clamp(1, 3);
        let (rho_s, rho_s_free) = self.shared(channels, cap);
        let mut free = [false; 7];
        free[6] = rho_s_free;
        let mut out = Albedos {
            rho_d: [T::zero(); 3],
            rho_ss: [T::zero(); 3],
            rho_s,
        };
        for c in 0..3 {
            let src = c.min(channels - 1);
            let (ga, gb) = self.shifted(src, rho_s);
            let [haa, hab, hbb] = self.h[src];
            let face = best_face(haa.re(), hab.re(), hbb.re(), ga.re(), gb.re(), cap);
            let (d, ss) = at_face(face, haa, hab, hbb, ga, gb);
            out.rho_d[c] = d;
            out.rho_ss[c] = ss;
            if c < channels {
                free[c] = matches!(face, Face::Free | Face::DFree(_));
                free[3 + c] = matches!(face, Face::Free | Face::SsFree(_));
            }
        }
        (out, free)
    }

    /// The quadratic's Hessian in the layout of [`AlbedoSystem::solve_faces`] (real parts).
    pub fn hessian(&self) -> [[f64; 7]; 7] {
        let mut h = [[0.0; 7]; 7];
        for c in 0..3 {
            let [haa, hab, hbb] = self.h[c].map(|v| v.re());
            let [hx, hy] = self.hs[c].map(|v| v.re());
            h[c][c] = haa;
            h[c][3 + c] = hab;
            h[3 + c][c] = hab;
            h[3 + c][3 + c] = hbb;
            h[c][6] = hx;
            h[6][c] = hx;
            h[3 + c][6] = hy;
            h[6][3 + c] = hy;
        }
        h[6][6] = self.hss.re();
        h
    }

    /// g_c − ρ_s·h_c: channel c's right-hand side for a given ρ_s.
    fn shifted(&self, c: usize, rho_s: T) -> (T, T) {
        (
            self.g[c][0] - rho_s * self.hs[c][0],
            self.g[c][1] - rho_s * self.hs[c][1],
        )
    }

    /// For the faces `faces` (one per channel): the numerator and denominator of the root of
    /// φ′ on that piece, ρ_s = (g_s − Σ num)/(h_ss − Σ den) (module doc).
    fn piece(&self, faces: &[Face], channels: usize) -> (T, T) {
        let k = T::from_f64;
        let mut num = T::zero();
        let mut den = T::zero();
        for (c, face) in faces.iter().enumerate().take(channels) {
            let [haa, hab, hbb] = self.h[c];
            let [hx, hy] = self.hs[c];
            let [ga, gb] = self.g[c];
            match *face {
                Face::Free => {
                    let det = haa * hbb - hab * hab;
                    // H⁻¹ = [[hbb, −hab], [−hab, haa]]/det.
                    let ux = (hbb * hx - hab * hy) / det;
                    let uy = (haa * hy - hab * hx) / det;
                    num += ux * ga + uy * gb;
                    den += ux * hx + uy * hy;
                }
                Face::DFree(y) => {
                    num += hx * (ga - hab * k(y)) / haa + hy * k(y);
                    den += hx * hx / haa;
                }
                Face::SsFree(x) => {
                    num += hy * (gb - hab * k(x)) / hbb + hx * k(x);
                    den += hy * hy / hbb;
                }
                Face::Corner(x, y) => num += hx * k(x) + hy * k(y),
            }
        }
        (self.gs - num, self.hss - den)
    }

    /// ρ_s at the minimum (module doc), in `T` with the final faces fixed, and whether it is
    /// free (inside the box, from its piece's linear equation).
    fn shared(&self, channels: usize, cap: f64) -> (T, bool) {
        let re = |v: T| v.re();
        // φ′(ρ) and the faces there, in f64.
        let slope_at = |rho: f64| -> (f64, [Face; 3]) {
            let mut faces = [Face::Corner(0.0, 0.0); 3];
            let mut d = re(self.hss) * rho - re(self.gs);
            for (c, face) in faces.iter_mut().enumerate().take(channels) {
                let [haa, hab, hbb] = self.h[c].map(re);
                let ga = re(self.g[c][0]) - rho * re(self.hs[c][0]);
                let gb = re(self.g[c][1]) - rho * re(self.hs[c][1]);
                *face = best_face(haa, hab, hbb, ga, gb, cap);
                let (x, y) = at_face(*face, haa, hab, hbb, ga, gb);
                d += re(self.hs[c][0]) * x + re(self.hs[c][1]) * y;
            }
            (d, faces)
        };
        if re(self.hss) <= 0.0 {
            // The specular lobe predicts nothing here: ρ_s is not determined; it stays 0.
            return (T::zero(), false);
        }
        let (d0, _) = slope_at(0.0);
        if d0 >= 0.0 || !d0.is_finite() {
            return (T::zero(), false);
        }
        let (dc, _) = slope_at(cap);
        if dc <= 0.0 {
            return (T::from_f64(cap), false);
        }
        // Root of the monotone piecewise-linear φ′ in (lo, hi): Newton to the root of the
        // current piece, kept inside the bracket (bisection otherwise); a piece whose root lies
        // in the piece itself is the answer.
        let (mut lo, mut hi) = (0.0, cap);
        let mut rho = 0.5 * cap;
        let mut faces = slope_at(rho).1;
        for _ in 0..64 {
            let (num, den) = self.piece(&faces, channels);
            let root = if den.re() > 0.0 {
                num.re() / den.re()
            } else {
                f64::NAN
            };
            if root.is_finite() && root > lo && root < hi {
                let (d, at_root) = slope_at(root);
                if at_root[..channels] == faces[..channels] {
                    // Exact: the piece's root lies on the piece.
                    return (num / den, true);
                }
                if d < 0.0 {
                    lo = root;
                } else {
                    hi = root;
                }
                rho = root;
                faces = at_root;
            } else {
                rho = 0.5 * (lo + hi);
                let (d, at) = slope_at(rho);
                if d < 0.0 {
                    lo = rho;
                } else {
                    hi = rho;
                }
                faces = at;
            }
            if hi - lo <= 1e-15 * cap {
                break;
            }
        }
        // Not resolved to a piece within the iteration cap (a root on a breakpoint): the
        // bracket's midpoint, a constant.
        (T::from_f64(rho.clamp(0.0, cap)), false)
    }
}

/// The face of [0, cap]² holding the minimum of ½[x y]H[x y]ᵀ − [x y]·g for a 2×2 symmetric
/// H ⪰ 0: every candidate of the active-set enumeration (the free optimum; each variable free
/// on the four edges with the other at 0 or at the cap; the four corners) is scored by the
/// exact objective and the best feasible one wins. A zero diagonal (a lobe that predicts
/// nothing) keeps that variable at 0.
fn best_face(haa: f64, hab: f64, hbb: f64, ga: f64, gb: f64, cap: f64) -> Face {
    let objective =
        |x: f64, y: f64| 0.5 * (haa * x * x + 2.0 * hab * x * y + hbb * y * y) - ga * x - gb * y;
    let inside = |v: f64| v > 0.0 && v < cap;
    let mut best = (0.0, Face::Corner(0.0, 0.0));
    let mut consider = |o: f64, face: Face| {
        if o < best.0 {
            best = (o, face);
        }
    };
    let det = haa * hbb - hab * hab;
    // Relative test: H is numerically singular below 1e-12 of its diagonal product.
    if det > 1e-12 * haa * hbb && det > 0.0 {
        let x = (hbb * ga - hab * gb) / det;
        let y = (haa * gb - hab * ga) / det;
        if inside(x) && inside(y) {
            consider(objective(x, y), Face::Free);
        }
    }
    for y in [0.0, cap] {
        if haa > 0.0 {
            let x = (ga - hab * y) / haa;
            if inside(x) {
                consider(objective(x, y), Face::DFree(y));
            }
        }
    }
    for x in [0.0, cap] {
        if hbb > 0.0 {
            let y = (gb - hab * x) / hbb;
            if inside(y) {
                consider(objective(x, y), Face::SsFree(x));
            }
        }
    }
    for (x, y) in [(cap, 0.0), (0.0, cap), (cap, cap)] {
        consider(objective(x, y), Face::Corner(x, y));
    }
    best.1
}

/// The minimiser on `face` in `T` (free variables from the face's linear equations, bounds as
/// constants).
fn at_face<T: Real>(face: Face, haa: T, hab: T, hbb: T, ga: T, gb: T) -> (T, T) {
    let k = T::from_f64;
    match face {
        Face::Free => {
            let det = haa * hbb - hab * hab;
            ((hbb * ga - hab * gb) / det, (haa * gb - hab * ga) / det)
        }
        Face::DFree(y) => ((ga - hab * k(y)) / haa, k(y)),
        Face::SsFree(x) => (k(x), (gb - hab * k(x)) / hbb),
        Face::Corner(x, y) => (k(x), k(y)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ellipso_model::optics::Dual;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Brute force over a fine grid refined by coordinate descent: the minimum of the same
    /// quadratic over the box.
    fn brute(rows: &[(usize, f64, f64, f64, f64, f64)], cap: f64) -> f64 {
        let q = |x: &[f64; 7]| {
            rows.iter()
                .map(|&(c, w, a, b, s, o)| {
                    let r = x[c] * a + x[3 + c] * b + x[6] * s - o;
                    w * r * r
                })
                .sum::<f64>()
        };
        let mut x = [0.0; 7];
        let mut best = q(&x);
        let mut step = cap / 2.0;
        while step > 1e-10 {
            let mut improved = true;
            while improved {
                improved = false;
                for i in 0..7 {
                    for d in [-step, step] {
                        let mut y = x;
                        y[i] = (y[i] + d).clamp(0.0, cap);
                        let v = q(&y);
                        if v < best - 1e-15 * best.abs() {
                            best = v;
                            x = y;
                            improved = true;
                        }
                    }
                }
            }
            step *= 0.5;
        }
        best
    }

    fn random_rows(rng: &mut ChaCha8Rng, channels: usize) -> Vec<(usize, f64, f64, f64, f64, f64)> {
        let truth: [f64; 7] = core::array::from_fn(|_| rng.random_range(-0.5..2.0));
        (0..24)
            .map(|k| {
                let c = k % channels;
                let a = rng.random_range(0.0..1.0);
                let b = rng.random_range(0.0..0.5);
                let s = if rng.random_bool(0.7) {
                    rng.random_range(0.0..0.8)
                } else {
                    0.0
                };
                let o =
                    truth[c] * a + truth[3 + c] * b + truth[6] * s + rng.random_range(-0.1..0.1);
                (c, rng.random_range(0.5..2.0), a, b, s, o)
            })
            .collect()
    }

    fn system<T: Real>(rows: &[(usize, f64, f64, f64, f64, f64)]) -> AlbedoSystem<T> {
        let k = T::from_f64;
        let mut sys = AlbedoSystem::new();
        for &(c, w, a, b, s, o) in rows {
            sys.add_row(c, k(w), k(a), k(b), k(s), k(o));
        }
        sys
    }

    #[test]
    fn solve_is_the_box_minimum() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let cap = 1.5;
        for trial in 0..300 {
            let channels = if trial % 3 == 0 { 1 } else { 3 };
            let rows = random_rows(&mut rng, channels);
            let x = system::<f64>(&rows).solve(channels, cap);
            let mine: f64 = rows
                .iter()
                .map(|&(c, w, a, b, s, o)| {
                    let r = x.rho_d[c] * a + x.rho_ss[c] * b + x.rho_s * s - o;
                    w * r * r
                })
                .sum();
            for v in x.rho_d.iter().chain(&x.rho_ss).chain([&x.rho_s]) {
                assert!((0.0..=cap).contains(v), "{x:?}");
            }
            let best = brute(&rows, cap);
            assert!(
                mine <= best + 1e-9 * (1.0 + best),
                "trial {trial}: {mine} vs brute force {best}, {x:?}"
            );
        }
    }

    #[test]
    fn dual_derivatives_match_central_differences() {
        // Rows depending on a parameter t: the solution's derivative along t.
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let cap = 2.0;
        let mut checked = 0;
        for _ in 0..100 {
            let rows = random_rows(&mut rng, 3);
            let dirs: Vec<[f64; 3]> = rows
                .iter()
                .map(|_| core::array::from_fn(|_| rng.random_range(-0.3..0.3)))
                .collect();
            let at = |t: Dual<1>| {
                let mut sys = AlbedoSystem::<Dual<1>>::new();
                for (&(c, w, a, b, s, o), d) in rows.iter().zip(&dirs) {
                    let k = Dual::<1>::constant;
                    sys.add_row(
                        c,
                        k(w),
                        k(a) + t * d[0],
                        k(b) + t * d[1],
                        k(s) + t * d[2],
                        k(o),
                    );
                }
                sys.solve(3, cap)
            };
            let x = at(Dual::variable(0.0, 0));
            let h = 1e-7;
            let (p, m) = (at(Dual::constant(h)), at(Dual::constant(-h)));
            let fields = |x: &Albedos<Dual<1>>| {
                let mut v: Vec<Dual<1>> = x.rho_d.to_vec();
                v.extend(x.rho_ss);
                v.push(x.rho_s);
                v
            };
            let (fx, fp, fm) = (fields(&x), fields(&p), fields(&m));
            // Skip draws on a breakpoint (a face change inside ±h).
            let smooth = fx.iter().zip(&fp).zip(&fm).all(|((x, p), m)| {
                let fd = (p.re - m.re) / (2.0 * h);
                (fd - x.du[0]).abs() < 1e-5 * (1.0 + fd.abs())
            });
            if smooth {
                checked += 1;
            }
        }
        assert!(checked > 90, "{checked} of 100 draws had exact derivatives");
    }

    #[test]
    fn a_lobe_that_predicts_nothing_keeps_its_albedo_at_zero() {
        let mut sys = AlbedoSystem::<f64>::new();
        for k in 0..10 {
            let a = 0.1 + 0.05 * k as f64;
            sys.add_row(0, 1.0, a, 0.0, 0.0, 0.4 * a);
        }
        let x = sys.solve(1, 5.0);
        assert!((x.rho_d[0] - 0.4).abs() < 1e-12, "{x:?}");
        assert_eq!((x.rho_ss[0], x.rho_s), (0.0, 0.0));
        assert_eq!(x.rho_d[2], x.rho_d[0]);
    }
}
