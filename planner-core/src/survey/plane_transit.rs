//! A plane's transit from one pose to another keeping out of the keep-out
//! area: one Dubins word if one is clear; else a search over a lattice of
//! poses (hybrid A*: arcs of the turn radius and straights between
//! headings 22.5° apart), its poses then joined by the longest clear Dubins
//! words; else Dubins words through the corners of the NFZ-avoiding path.

use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap};
use std::f64::consts::TAU;

use super::plane_flight::PlaneFlight;
use super::request::PlanError;
use crate::coverage::dubins::{Piece, Pose, dubins_iter, dubins_length, end_pose};
use crate::flock::ObstacleMap;

/// Headings of the lattice (a turn of 2π / this per arc).
const HEADINGS: usize = 16;
/// Most poses the lattice search expands before it gives up.
const MAX_EXPANSIONS: usize = 6000;
/// The search's greed: the estimate (the Dubins length to the goal) is
/// weighted by this (1 would be A*'s shortest path, slower).
const GREED: f64 = 1.5;
/// Dubins words tried from each pose expanded straight to the goal.
const SHOT_WORDS: usize = 2;
/// Within this many turn radii of the goal every pose expanded tries a
/// shot at it.
const SHOT_RANGE: f64 = 6.0;
/// Poses ahead a Dubins word may skip at once when smoothing a path.
const LOOKAHEAD: usize = 12;

impl PlaneFlight<'_> {
    /// From pose `a` to pose `b` keeping out of the keep-out area (see the
    /// module's doc); a fault naming the place when nothing is found.
    pub(super) fn connect(&self, a: Pose, b: Pose) -> Result<Vec<Piece>, PlanError> {
        if let Some(w) = self.dubins_clear(a, b) {
            return Ok(w);
        }
        crate::cancel::check()?;
        if let Some(w) = self.lattice(a, b) {
            return Ok(w);
        }
        // The search with corners a turn radius out first, then (a field
        // too dense for that) with the bare corners.
        self.chain(&self.routes, a, b)
            .or_else(|| self.chain(self.obstacles, a, b))
            .ok_or_else(|| self.fault(a.at, "the transit"))
    }

    /// `poses` joined in order: from each pose reached, the clear Dubins
    /// word to the farthest of the next [`LOOKAHEAD`] poses, else
    /// `fallback(i)` to the next one; `None` when that fails too.
    fn thread(
        &self,
        poses: &[Pose],
        mut fallback: impl FnMut(usize) -> Option<Vec<Piece>>,
    ) -> Option<Vec<Piece>> {
        let mut out = Vec::new();
        let mut i = 0;
        while i + 1 < poses.len() {
            crate::cancel::check().ok()?;
            let far = (i + LOOKAHEAD).min(poses.len() - 1);
            let (j, w) = (i + 1..=far)
                .rev()
                .find_map(|j| self.dubins_clear(poses[i], poses[j]).map(|w| (j, w)))
                .or_else(|| fallback(i).map(|w| (i + 1, w)))?;
            out.extend(w);
            i = j;
        }
        Some(out)
    }

    /// Dubins words through the corners of `map`'s NFZ-avoiding path from
    /// `a` to `b` (headed along the bisector of its legs), else through a
    /// detour or out of a pocket; `None` when stuck.
    fn chain(&self, map: &ObstacleMap, a: Pose, b: Pose) -> Option<Vec<Piece>> {
        let path = map.shortest_path(a.at, b.at).ok()?;
        let mut poses = vec![a];
        for i in 1..path.len().saturating_sub(1) {
            let (p, c, n) = (path[i - 1], path[i], path[i + 1]);
            let d = unit(c - p) + unit(n - c);
            poses.push(Pose::new(c, d.y.atan2(d.x)));
        }
        poses.push(b);
        self.thread(&poses, |i| {
            self.detour(poses[i], poses[i + 1])
                .or_else(|| self.escape(poses[i], poses[i + 1]))
        })
    }

    /// Hybrid A* from `a` to `b` over poses reached by arcs of the turn
    /// radius (a sixteenth of a turn either way) and straights as long,
    /// each checked clear, one pose kept per heading and half-step cell;
    /// from each pose expanded the shortest Dubins words to `b` are tried.
    /// The path found is smoothed by [`PlaneFlight::thread`]; `None` after
    /// [`MAX_EXPANSIONS`] poses.
    pub(super) fn lattice(&self, a: Pose, b: Pose) -> Option<Vec<Piece>> {
        let r = self.turns.radius_m;
        let turn = TAU / HEADINGS as f64;
        let step = r * turn;
        let cell = step / 2.0;
        let key = |p: &Pose, k: i64| {
            (
                ((p.at.x - a.at.x) / cell).floor() as i64,
                ((p.at.y - a.at.y) / cell).floor() as i64,
                k.rem_euclid(HEADINGS as i64),
            )
        };
        let mut nodes = vec![Node {
            pose: a,
            k: 0,
            g: 0.0,
            parent: usize::MAX,
            link: Vec::new(),
        }];
        let mut best: HashMap<(i64, i64, i64), f64> = HashMap::new();
        let mut open = BinaryHeap::new();
        open.push(Open {
            f: dubins_length(a, b, r),
            node: 0,
        });
        let mut expanded = 0;
        while let Some(Open { node, .. }) = open.pop() {
            let here = nodes[node].pose;
            let (k, g) = (nodes[node].k, nodes[node].g);
            if best.get(&key(&here, k)).is_some_and(|&v| v < g) {
                continue;
            }
            expanded += 1;
            if expanded > MAX_EXPANSIONS || (expanded % 256 == 0 && crate::cancel::check().is_err())
            {
                return None;
            }
            // Far from the goal a straight shot is seldom clear: tried on
            // every eighth pose only.
            let near = (here.at.x - b.at.x).hypot(here.at.y - b.at.y) < SHOT_RANGE * r;
            if (near || expanded % 8 == 1)
                && let Some(shot) = dubins_iter(here, b, r)
                    .take(SHOT_WORDS)
                    .find(|w| self.all_clear(w))
            {
                return Some(self.smooth(&nodes, node, shot, b));
            }
            for (dk, piece) in [
                (1, self.arc_from(here, 1.0, turn)),
                (
                    0,
                    Piece::Line {
                        from: here.at,
                        to: here.ahead(step).at,
                    },
                ),
                (-1, self.arc_from(here, -1.0, turn)),
            ] {
                let pose = end_pose(&piece, here.heading);
                let (kn, gn) = (k + dk, g + step);
                let slot = key(&pose, kn);
                if best.get(&slot).is_some_and(|&v| v <= gn) || !self.clear(&piece) {
                    continue;
                }
                best.insert(slot, gn);
                nodes.push(Node {
                    pose,
                    k: kn,
                    g: gn,
                    parent: node,
                    link: vec![piece],
                });
                open.push(Open {
                    f: gn + GREED * dubins_length(pose, b, r),
                    node: nodes.len() - 1,
                });
            }
        }
        None
    }

    /// The lattice path to `nodes[last]` and on by `shot` to `b`, its poses
    /// joined by the longest clear Dubins words.
    fn smooth(&self, nodes: &[Node], last: usize, shot: Vec<Piece>, b: Pose) -> Vec<Piece> {
        let mut chain = vec![last];
        while let Some(&n) = chain.last() {
            if nodes[n].parent == usize::MAX {
                break;
            }
            chain.push(nodes[n].parent);
        }
        chain.reverse();
        let mut poses: Vec<Pose> = chain.iter().map(|&n| nodes[n].pose).collect();
        poses.push(b);
        let mut links: Vec<Vec<Piece>> =
            chain[1..].iter().map(|&n| nodes[n].link.clone()).collect();
        links.push(shot);
        let joined = self.thread(&poses, |i| Some(links[i].clone()));
        // Cancelled while smoothing: the lattice path as found.
        joined.unwrap_or_else(|| links.concat())
    }
}

/// A pose reached by the lattice search: its heading's index, the length
/// flown to it, the pose it came from and the piece from there.
struct Node {
    pose: Pose,
    k: i64,
    g: f64,
    parent: usize,
    link: Vec<Piece>,
}

/// A pose waiting in the search's queue, by its estimate.
struct Open {
    f: f64,
    node: usize,
}

impl PartialEq for Open {
    fn eq(&self, other: &Self) -> bool {
        self.cmp(other) == Ordering::Equal
    }
}

impl Eq for Open {}

impl PartialOrd for Open {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Open {
    /// Smallest estimate first (the heap is a max-heap), then the earlier
    /// pose, so the search is deterministic.
    fn cmp(&self, other: &Self) -> Ordering {
        other
            .f
            .total_cmp(&self.f)
            .then_with(|| other.node.cmp(&self.node))
    }
}

fn unit(c: geo_types::Coord<f64>) -> geo_types::Coord<f64> {
    let l = c.x.hypot(c.y);
    if l > 0.0 { c / l } else { c }
}
