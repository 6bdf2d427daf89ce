//! Dubins paths (Dubins 1957; the closed forms of Shkel & Lumelsky 2001):
//! the shortest ways from one heading to another with a smallest turn
//! radius, as straight lines and circular arcs.

use std::f64::consts::TAU;

use geo_types::Coord;

/// A position with a heading (radians, counter-clockwise from +x).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    pub at: Coord<f64>,
    pub heading: f64,
}

impl Pose {
    pub fn new(at: Coord<f64>, heading: f64) -> Pose {
        Pose { at, heading }
    }

    /// The pose facing from `a` towards `b`.
    pub fn towards(a: Coord<f64>, b: Coord<f64>) -> Pose {
        Pose::new(a, (b.y - a.y).atan2(b.x - a.x))
    }

    pub fn direction(&self) -> Coord<f64> {
        Coord {
            x: self.heading.cos(),
            y: self.heading.sin(),
        }
    }

    /// `d` metres ahead (behind when negative), same heading.
    pub fn ahead(&self, d: f64) -> Pose {
        Pose::new(self.at + self.direction() * d, self.heading)
    }
}

/// One piece of a flown path: a straight line or an arc.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Piece {
    Line {
        from: Coord<f64>,
        to: Coord<f64>,
    },
    /// An arc round `centre` of `radius`, starting at angle `start` (of the
    /// point on the circle, radians) and sweeping `sweep` (positive
    /// counter-clockwise, a left turn).
    Arc {
        centre: Coord<f64>,
        radius: f64,
        start: f64,
        sweep: f64,
    },
}

impl Piece {
    pub fn length(&self) -> f64 {
        match *self {
            Piece::Line { from, to } => (to.x - from.x).hypot(to.y - from.y),
            Piece::Arc { radius, sweep, .. } => radius * sweep.abs(),
        }
    }

    /// The point at fraction `t` ∈ [0, 1] of the piece.
    pub fn point(&self, t: f64) -> Coord<f64> {
        match *self {
            Piece::Line { from, to } => from + (to - from) * t,
            Piece::Arc {
                centre,
                radius,
                start,
                sweep,
            } => {
                let a = start + sweep * t;
                centre
                    + Coord {
                        x: radius * a.cos(),
                        y: radius * a.sin(),
                    }
            }
        }
    }

    pub fn start(&self) -> Coord<f64> {
        self.point(0.0)
    }

    /// This piece and `next` (which starts where this one ends) as one
    /// piece, if they are two arcs of one circle turning the same way or
    /// two lines in one direction.
    pub fn joined(&self, next: &Piece) -> Option<Piece> {
        const TOL: f64 = 1e-7;
        match (*self, *next) {
            (
                Piece::Arc {
                    centre,
                    radius,
                    start,
                    sweep,
                },
                Piece::Arc {
                    centre: c2,
                    radius: r2,
                    start: s2,
                    sweep: w2,
                },
            ) => {
                let same_circle = (centre.x - c2.x).hypot(centre.y - c2.y) < TOL * radius.max(1.0)
                    && (radius - r2).abs() < TOL * radius.max(1.0);
                let continues = (start + sweep - s2 + std::f64::consts::PI)
                    .rem_euclid(std::f64::consts::TAU)
                    - std::f64::consts::PI;
                (same_circle && sweep * w2 > 0.0 && continues.abs() < TOL).then_some(Piece::Arc {
                    centre,
                    radius,
                    start,
                    sweep: sweep + w2,
                })
            }
            (Piece::Line { from, to }, Piece::Line { from: f2, to: t2 }) => {
                let (u, v) = (to - from, t2 - f2);
                let cross = u.x * v.y - u.y * v.x;
                let dot = u.x * v.x + u.y * v.y;
                (dot > 0.0 && cross.abs() < TOL * dot && (to.x - f2.x).hypot(to.y - f2.y) < TOL)
                    .then_some(Piece::Line { from, to: t2 })
            }
            _ => None,
        }
    }

    pub fn end(&self) -> Coord<f64> {
        self.point(1.0)
    }
}

/// The segment kinds of a Dubins word.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Seg {
    L,
    S,
    R,
}

const WORDS: [[Seg; 3]; 6] = [
    [Seg::L, Seg::S, Seg::L],
    [Seg::R, Seg::S, Seg::R],
    [Seg::L, Seg::S, Seg::R],
    [Seg::R, Seg::S, Seg::L],
    [Seg::R, Seg::L, Seg::R],
    [Seg::L, Seg::R, Seg::L],
];

fn mod2pi(a: f64) -> f64 {
    a.rem_euclid(TAU)
}

/// The three segment lengths (normalised by the radius) of word `w`, if it
/// exists, for the normalised problem (`d`, `alpha`, `beta`).
fn word_params(w: usize, d: f64, alpha: f64, beta: f64) -> Option<[f64; 3]> {
    let (sa, sb, ca, cb) = (alpha.sin(), beta.sin(), alpha.cos(), beta.cos());
    let c_ab = (alpha - beta).cos();
    match w {
        0 => {
            let p2 = 2.0 + d * d - 2.0 * c_ab + 2.0 * d * (sa - sb);
            (p2 >= 0.0).then(|| {
                let t = (cb - ca).atan2(d + sa - sb);
                [mod2pi(t - alpha), p2.sqrt(), mod2pi(beta - t)]
            })
        }
        1 => {
            let p2 = 2.0 + d * d - 2.0 * c_ab + 2.0 * d * (sb - sa);
            (p2 >= 0.0).then(|| {
                let t = (ca - cb).atan2(d - sa + sb);
                [mod2pi(alpha - t), p2.sqrt(), mod2pi(t - beta)]
            })
        }
        2 => {
            let p2 = -2.0 + d * d + 2.0 * c_ab + 2.0 * d * (sa + sb);
            (p2 >= 0.0).then(|| {
                let p = p2.sqrt();
                let t = (-ca - cb).atan2(d + sa + sb) - (-2.0f64).atan2(p);
                [mod2pi(t - alpha), p, mod2pi(t - mod2pi(beta))]
            })
        }
        3 => {
            let p2 = -2.0 + d * d + 2.0 * c_ab - 2.0 * d * (sa + sb);
            (p2 >= 0.0).then(|| {
                let p = p2.sqrt();
                let t = (ca + cb).atan2(d - sa - sb) - 2.0f64.atan2(p);
                [mod2pi(alpha - t), p, mod2pi(beta - t)]
            })
        }
        4 => {
            let c = (6.0 - d * d + 2.0 * c_ab + 2.0 * d * (sa - sb)) / 8.0;
            (c.abs() <= 1.0).then(|| {
                let phi = (ca - cb).atan2(d - sa + sb);
                let p = mod2pi(TAU - c.acos());
                let t = mod2pi(alpha - phi + mod2pi(p / 2.0));
                [t, p, mod2pi(alpha - beta - t + mod2pi(p))]
            })
        }
        _ => {
            let c = (6.0 - d * d + 2.0 * c_ab + 2.0 * d * (sb - sa)) / 8.0;
            (c.abs() <= 1.0).then(|| {
                let phi = (ca - cb).atan2(d + sa - sb);
                let p = mod2pi(TAU - c.acos());
                let t = mod2pi(-alpha - phi + p / 2.0);
                [t, p, mod2pi(mod2pi(beta) - alpha - t + mod2pi(p))]
            })
        }
    }
}

/// The problem from `a` to `b` normalised by `radius`: distance, and both
/// headings against the line between them.
fn normalised(a: Pose, b: Pose, radius: f64) -> (f64, f64, f64) {
    let (dx, dy) = (b.at.x - a.at.x, b.at.y - a.at.y);
    let theta = mod2pi(dy.atan2(dx));
    (
        dx.hypot(dy) / radius,
        mod2pi(a.heading - theta),
        mod2pi(b.heading - theta),
    )
}

/// The words that exist from `a` to `b`, as (normalised length, word,
/// segment lengths), shortest first.
fn words(a: Pose, b: Pose, radius: f64) -> Vec<(f64, usize, [f64; 3])> {
    let (d, alpha, beta) = normalised(a, b, radius);
    let mut found: Vec<(f64, usize, [f64; 3])> = (0..WORDS.len())
        .filter_map(|w| {
            let params = word_params(w, d, alpha, beta)?;
            params
                .iter()
                .all(|p| p.is_finite())
                .then(|| (params.iter().sum::<f64>(), w, params))
        })
        .collect();
    found.sort_by(|x, y| x.0.total_cmp(&y.0));
    found
}

/// Every Dubins path from `a` to `b` with turns of `radius`, shortest
/// first, each as its pieces (zero-length pieces left out).
pub fn dubins_paths(a: Pose, b: Pose, radius: f64) -> Vec<Vec<Piece>> {
    dubins_iter(a, b, radius).collect()
}

/// [`dubins_paths`], each word's pieces built only when it is reached
/// (for callers that stop at the first word that suits them).
pub fn dubins_iter(a: Pose, b: Pose, radius: f64) -> impl Iterator<Item = Vec<Piece>> {
    words(a, b, radius)
        .into_iter()
        .map(move |(_, w, params)| pieces(a, &WORDS[w], params, radius))
}

/// Length of the shortest Dubins path from `a` to `b` (no pieces built).
pub fn dubins_length(a: Pose, b: Pose, radius: f64) -> f64 {
    let (d, alpha, beta) = normalised(a, b, radius);
    (0..WORDS.len())
        .filter_map(|w| word_params(w, d, alpha, beta))
        .map(|p| p.iter().sum::<f64>())
        .filter(|l| l.is_finite())
        .fold(f64::INFINITY, f64::min)
        * radius
}

/// The pieces of one word from `pose`.
fn pieces(mut pose: Pose, word: &[Seg; 3], params: [f64; 3], radius: f64) -> Vec<Piece> {
    let mut out = Vec::with_capacity(3);
    for (seg, &p) in word.iter().zip(&params) {
        if p * radius < 1e-9 {
            continue;
        }
        let piece = match seg {
            Seg::S => {
                let to = pose.ahead(p * radius).at;
                Piece::Line { from: pose.at, to }
            }
            Seg::L | Seg::R => {
                let side = if *seg == Seg::L { 1.0 } else { -1.0 };
                // The centre lies to the left (right) of the heading.
                let normal = pose.heading + side * std::f64::consts::FRAC_PI_2;
                let centre = pose.at
                    + Coord {
                        x: radius * normal.cos(),
                        y: radius * normal.sin(),
                    };
                Piece::Arc {
                    centre,
                    radius,
                    start: normal + std::f64::consts::PI,
                    sweep: side * p,
                }
            }
        };
        pose = end_pose(&piece, pose.heading);
        out.push(piece);
    }
    out
}

/// The pose at the end of `piece`, entered with `heading`.
pub fn end_pose(piece: &Piece, heading: f64) -> Pose {
    match *piece {
        Piece::Line { to, .. } => Pose::new(to, heading),
        Piece::Arc { sweep, .. } => Pose::new(piece.end(), heading + sweep),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::{FRAC_PI_2, PI};

    fn c(x: f64, y: f64) -> Coord<f64> {
        Coord { x, y }
    }

    fn same_angle(a: f64, b: f64) -> bool {
        let d = mod2pi(a - b);
        d < 1e-9 || TAU - d < 1e-9
    }

    /// Every word found ends at the goal with the goal's heading, and its
    /// pieces join with continuous headings.
    #[test]
    fn every_word_reaches_the_goal() {
        let starts = [
            Pose::new(c(0., 0.), 0.0),
            Pose::new(c(5., -3.), 2.0),
            Pose::new(c(-40., 10.), -1.0),
        ];
        let goals = [
            Pose::new(c(100., 0.), PI),
            Pose::new(c(10., 20.), 0.5),
            Pose::new(c(0., 30.), PI),
            Pose::new(c(-60., -80.), -2.5),
        ];
        for a in starts {
            for b in goals {
                let paths = dubins_paths(a, b, 20.0);
                assert!(!paths.is_empty());
                for path in &paths {
                    let mut pose = a;
                    for piece in path {
                        let s = piece.start();
                        assert!((s.x - pose.at.x).hypot(s.y - pose.at.y) < 1e-6);
                        pose = end_pose(piece, pose.heading);
                    }
                    assert!((pose.at.x - b.at.x).hypot(pose.at.y - b.at.y) < 1e-6);
                    assert!(same_angle(pose.heading, b.heading));
                }
                let lengths: Vec<f64> = paths
                    .iter()
                    .map(|p| p.iter().map(Piece::length).sum())
                    .collect();
                assert!(lengths.windows(2).all(|w| w[0] <= w[1] + 1e-12));
            }
        }
    }

    #[test]
    fn known_lengths() {
        // A U-turn to a lane 40 m over with radius 20: two quarter circles.
        let a = Pose::new(c(0., 0.), FRAC_PI_2);
        let b = Pose::new(c(40., 0.), -FRAC_PI_2);
        assert!((dubins_length(a, b, 20.0) - 20.0 * PI).abs() < 1e-9);
        // Straight ahead.
        let b = Pose::new(c(0., 50.), FRAC_PI_2);
        assert!((dubins_length(a, b, 20.0) - 50.0).abs() < 1e-9);
        // A lane 10 m over with radius 20: a loop (CCC) turn, longer than
        // the half circle a 40 m spacing needs: 51.3° + 282.7° + 51.3°.
        let b = Pose::new(c(10., 0.), -FRAC_PI_2);
        let l = dubins_length(a, b, 20.0);
        let side = (25.0f64 / 40.0).acos();
        let want = 20.0 * (4.0 * side + PI);
        assert!((l - want).abs() < 1e-9, "{l} {want}");
    }
}
