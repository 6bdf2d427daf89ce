//! The photos a survey takes: where and when each is taken and the ground
//! its image covers (its footprint, the corner rays met with the DEM or the
//! flat ground), kept in the plan lane by lane so that `photos.geojson` and
//! the cells' overlap figures need no DEM once planned.

use serde::{Deserialize, Serialize};

use super::capture::{Capture, distance_3d_to, photo_stations};
use super::terrain_flight::LegKind;
use crate::coverage::Camera;
use crate::flock::Tour;
use crate::terrain::{Point3, TerrainModel};

/// Farthest a ray is followed over a DEM, horizontally, m.
const MAX_RAY_M: f64 = 20_000.0;
/// Bisection steps refining where a ray meets the DEM (a step of metres
/// to well under a millimetre).
const BISECTIONS: usize = 30;

/// The camera as the footprints need it.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PhotoCamera {
    /// Pitch, degrees (−90 straight down), forward along the lane.
    pub pitch_deg: f64,
    /// Tangent of half the field of view across and along track.
    pub half_tan: [f64; 2],
    /// Ground sample distance per metre of range, cm/px (across track).
    pub gsd_cm_px_per_m: f64,
}

impl PhotoCamera {
    pub(super) fn new(camera: &Camera, pitch_deg: f64) -> PhotoCamera {
        let (across_mm, across_px) = camera.across_track();
        let f = camera.focal_length_mm;
        PhotoCamera {
            pitch_deg,
            half_tan: [across_mm / 2.0 / f, camera.along_track_mm() / 2.0 / f],
            gsd_cm_px_per_m: across_mm / f * 100.0 / across_px,
        }
    }

    /// Directions (east, north, up; grid axes) of the rays through the
    /// image's corners — near left, near right, far right, far left — and
    /// its centre, for a camera heading `heading_deg` (grid bearing) and
    /// tilted forward by the pitch (see `coverage/oblique.rs` for the frame).
    pub fn rays(&self, heading_deg: f64) -> [[f64; 3]; 5] {
        let t = (90.0 + self.pitch_deg).to_radians();
        let h = heading_deg.to_radians();
        let (ahead, right) = ([h.sin(), h.cos()], [h.cos(), -h.sin()]);
        let [w, a] = self.half_tan;
        let ray = |tx: f64, ty: f64| {
            let along = ty * t.cos() + t.sin();
            let up = ty * t.sin() - t.cos();
            [
                tx * right[0] + along * ahead[0],
                tx * right[1] + along * ahead[1],
                up,
            ]
        };
        [
            ray(-w, -a),
            ray(w, -a),
            ray(w, a),
            ray(-w, a),
            ray(0.0, 0.0),
        ]
    }
}

/// The photos of one lane, in flight order. Flat: evenly spaced from
/// `start` along `heading_deg`, at its height, evenly timed. Over a DEM the
/// per-photo members hold the heights, times and footprints.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PhotoLane {
    /// The cell the lane belongs to (its id in `cells`).
    pub cell: usize,
    /// The camera at the first photo: UTM easting, northing and height
    /// (above the take-off point on a flat survey; in the DEM's datum over
    /// a DEM), m.
    pub start: [f64; 3],
    /// Grid bearing of the lane (and the camera), degrees.
    pub heading_deg: f64,
    /// Ground distance between photos, m.
    pub spacing_m: f64,
    pub count: usize,
    /// Time of the first photo since take-off, s.
    pub time_s: f64,
    /// Time between photos (flat), s.
    pub interval_s: f64,
    /// Over a DEM: the camera height at each photo.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub heights: Vec<f64>,
    /// Over a DEM: the time of each photo since take-off, s.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub times_s: Vec<f64>,
    /// Over a DEM: each photo's footprint on it, the corner rays' and the
    /// centre ray's ground points (x, y, z each; corners as in
    /// [`PhotoCamera::rays`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub ground: Vec<[f64; 15]>,
}

/// The photos of one sortie.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SortiePhotos {
    pub camera: PhotoCamera,
    pub lanes: Vec<PhotoLane>,
}

/// One photo, its footprint worked out.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Photo {
    pub cell: usize,
    /// The lane's index in its sortie's [`SortiePhotos::lanes`].
    pub lane: usize,
    /// The camera: UTM easting, northing, height.
    pub camera: [f64; 3],
    pub heading_deg: f64,
    pub time_s: f64,
    /// Ground points of the image's corners (near left, near right, far
    /// right, far left) and centre.
    pub corners: [[f64; 3]; 4],
    pub centre: [f64; 3],
}

impl Photo {
    /// Ground sample distance at the image centre (its range times the
    /// camera's GSD per metre), cm/px.
    pub fn gsd_cm_px(&self, camera: &PhotoCamera) -> f64 {
        let d: f64 = (0..3)
            .map(|i| (self.centre[i] - self.camera[i]).powi(2))
            .sum();
        d.sqrt() * camera.gsd_cm_px_per_m
    }
}

impl SortiePhotos {
    /// Photos in the sortie.
    pub fn count(&self) -> usize {
        self.lanes.iter().map(|l| l.count).sum()
    }

    /// Every photo with its footprint, in flight order.
    pub fn photos(&self) -> impl Iterator<Item = Photo> + '_ {
        self.lanes
            .iter()
            .enumerate()
            .flat_map(move |(i, lane)| lane_photos(&self.camera, i, lane))
    }
}

fn lane_photos<'a>(
    camera: &PhotoCamera,
    index: usize,
    lane: &'a PhotoLane,
) -> impl Iterator<Item = Photo> + use<'a> {
    let rays = camera.rays(lane.heading_deg);
    let h = lane.heading_deg.to_radians();
    (0..lane.count).map(move |k| {
        let (camera_at, time_s, ground) = if lane.ground.len() == lane.count {
            let s = k as f64 * lane.spacing_m;
            let xy = [lane.start[0] + s * h.sin(), lane.start[1] + s * h.cos()];
            let g = lane.ground[k];
            let pt = |i: usize| [g[3 * i], g[3 * i + 1], g[3 * i + 2]];
            (
                [xy[0], xy[1], lane.heights[k]],
                lane.times_s[k],
                [pt(0), pt(1), pt(2), pt(3), pt(4)],
            )
        } else {
            let s = k as f64 * lane.spacing_m;
            let c = [
                lane.start[0] + s * h.sin(),
                lane.start[1] + s * h.cos(),
                lane.start[2],
            ];
            let hit = |d: &[f64; 3]| flat_hit(c, *d, 0.0);
            (
                c,
                lane.time_s + k as f64 * lane.interval_s,
                [
                    hit(&rays[0]),
                    hit(&rays[1]),
                    hit(&rays[2]),
                    hit(&rays[3]),
                    hit(&rays[4]),
                ],
            )
        };
        Photo {
            cell: lane.cell,
            lane: index,
            camera: camera_at,
            heading_deg: lane.heading_deg,
            time_s,
            corners: [ground[0], ground[1], ground[2], ground[3]],
            centre: ground[4],
        }
    })
}

/// Where the ray from `c` along `d` meets the level ground at height
/// `ground_z` (a ray not descending meets it far off, as a grazing one).
fn flat_hit(c: [f64; 3], d: [f64; 3], ground_z: f64) -> [f64; 3] {
    let k = (c[2] - ground_z) / (-d[2]).max(1e-9);
    [c[0] + k * d[0], c[1] + k * d[1], ground_z]
}

/// Where the ray from `c` along `d` first meets the DEM's surface: marched
/// every `step` metres (along the ray), then refined by bisection; where the
/// DEM has no heights along the ray, the level ground at `fallback_z`.
fn dem_hit(model: &TerrainModel, c: [f64; 3], d: [f64; 3], step: f64, fallback_z: f64) -> [f64; 3] {
    let norm = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let dk = step / norm;
    let at = |k: f64| [c[0] + k * d[0], c[1] + k * d[1], c[2] + k * d[2]];
    // Height of the ray above the ground at k (None without DEM data).
    let above = |k: f64| {
        let p = at(k);
        model
            .terrain(geo_types::Coord { x: p[0], y: p[1] })
            .map(|g| p[2] - g)
    };
    let horizontal = d[0].hypot(d[1]).max(1e-12);
    let k_max = (MAX_RAY_M / horizontal).min(MAX_RAY_M / (-d[2]).max(1e-9));
    let mut k0 = 0.0;
    let mut k = dk;
    while k <= k_max {
        if let Some(h) = above(k)
            && h <= 0.0
        {
            let (mut lo, mut hi) = (k0, k);
            for _ in 0..BISECTIONS {
                let mid = 0.5 * (lo + hi);
                if above(mid).is_some_and(|h| h <= 0.0) {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            return at(hi);
        }
        k0 = k;
        k += dk;
    }
    flat_hit(c, d, fallback_z)
}

/// Works out a sortie's photos as it is flown: where each lane's photos
/// are taken ([`Capture`]), when (the flight's clock: its 3D length at the
/// speed, a turn penalty per turn as the flight time counts them, the hover
/// stops), and over a DEM their footprints.
pub(super) struct PhotoPlanner<'a> {
    pub camera: PhotoCamera,
    pub capture: &'a Capture,
    pub speed_m_s: f64,
    pub turn_penalty_s: f64,
    /// The DEM, and the ground height used where it has none.
    pub model: Option<(&'a TerrainModel, f64)>,
}

impl PhotoPlanner<'_> {
    /// The photos of `tour` flown flat at `altitude` above the take-off
    /// point (climbed to vertically first).
    pub(super) fn flat(&self, tour: &Tour, altitude: f64) -> SortiePhotos {
        let at = |c: &geo_types::Coord<f64>| Point3 {
            x: c.x,
            y: c.y,
            z: altitude,
        };
        let mut clock = Clock::new(altitude / self.speed_m_s);
        let mut out = SortiePhotos {
            camera: self.camera,
            lanes: Vec::new(),
        };
        for (i, transit) in tour.transits.iter().enumerate() {
            clock.fly(self, transit.iter().map(at));
            let Some(visit) = tour.visits.get(i) else {
                continue;
            };
            for (k, lane) in visit.lanes.iter().enumerate() {
                let pts = [at(&lane.start), at(&lane.end)];
                self.lane(&mut out, &mut clock, visit.cell_index, &pts);
                if let Some(link) = visit.links.get(k) {
                    clock.fly(self, link.iter().map(at));
                }
            }
        }
        out
    }

    /// The photos of `tour` flown over the DEM along `legs` (its 3D legs in
    /// flight order, one lane leg per lane of the tour), climbing `climb_m`
    /// from home first.
    pub(super) fn over_dem(
        &self,
        tour: &Tour,
        legs: &[(LegKind, Vec<Point3>)],
        climb_m: f64,
    ) -> SortiePhotos {
        let mut clock = Clock::new(climb_m / self.speed_m_s);
        let mut out = SortiePhotos {
            camera: self.camera,
            lanes: Vec::new(),
        };
        let mut cells = tour
            .visits
            .iter()
            .flat_map(|v| v.lanes.iter().map(move |_| v.cell_index));
        for (kind, pts) in legs {
            match (
                kind,
                if *kind == LegKind::Lane {
                    cells.next()
                } else {
                    None
                },
            ) {
                (LegKind::Lane, Some(cell)) => self.lane(&mut out, &mut clock, cell, pts),
                _ => clock.fly(self, pts.iter().copied()),
            }
        }
        out
    }

    /// The photos of one lane flown through `pts`, then the lane flown.
    pub(super) fn lane(
        &self,
        out: &mut SortiePhotos,
        clock: &mut Clock,
        cell: usize,
        pts: &[Point3],
    ) {
        let (Some(first), Some(last)) = (pts.first(), pts.last()) else {
            return;
        };
        let (dx, dy) = (last.x - first.x, last.y - first.y);
        let heading_deg = dx.atan2(dy).to_degrees().rem_euclid(360.0);
        let length: f64 = pts
            .windows(2)
            .map(|w| (w[1].x - w[0].x).hypot(w[1].y - w[0].y))
            .sum();
        let count = self.capture.photos(length);
        let spacing = self.capture.spacing_m();
        // To the lane's start, and the turn onto it, before the first photo.
        clock.fly(self, std::iter::once(*first));
        clock.turn_to(self, dy.atan2(dx), dx.hypot(dy));
        let stop_s = self.capture.stop_time_s(1);
        // Rounded to keep plan.json small: the photos move by well under a
        // millimetre.
        let fine = |v: f64| (v * 1e7).round() / 1e7;
        let mut lane = PhotoLane {
            cell,
            start: round3([first.x, first.y, first.z]),
            heading_deg: fine(heading_deg),
            spacing_m: fine(spacing),
            count,
            time_s: round(clock.t),
            interval_s: fine(spacing / self.speed_m_s + stop_s),
            ..PhotoLane::default()
        };
        if let Some((model, fallback_z)) = self.model {
            let rays = self.camera.rays(heading_deg);
            // Half a DEM cell: a ray crossing a roof's corner is not
            // stepped over.
            let step = (model.cell_m() / 4.0).clamp(0.1, 5.0);
            for (k, (s, p)) in photo_stations(pts, spacing, count).into_iter().enumerate() {
                let c = [p.x, p.y, p.z];
                let mut g = [0.0; 15];
                for (i, d) in rays.iter().enumerate() {
                    let hit = dem_hit(model, c, *d, step, fallback_z);
                    g[3 * i..3 * i + 3].copy_from_slice(&round3(hit));
                }
                lane.heights.push(round(p.z));
                let t = clock.t + distance_3d_to(pts, s) / self.speed_m_s + k as f64 * stop_s;
                lane.times_s.push(round(t));
                lane.ground.push(g);
            }
        }
        clock.fly(self, pts.iter().copied());
        clock.t += self.capture.stop_time_s(count);
        out.lanes.push(lane);
    }
}

/// Time since take-off along a flight, with the heading last flown (turns
/// counted as `flock::count_turns` counts them).
pub(super) struct Clock {
    t: f64,
    last: Option<Point3>,
    heading: Option<f64>,
}

impl Clock {
    pub(super) fn new(t: f64) -> Clock {
        Clock {
            t,
            last: None,
            heading: None,
        }
    }

    /// A segment of horizontal length `len` heading `h` (radians from east)
    /// begins: a turn when it changes the heading by more than a turn.
    fn turn_to(&mut self, p: &PhotoPlanner, h: f64, len: f64) {
        if len <= 1e-6 {
            return;
        }
        if let Some(prev) = self.heading {
            let mut d = (h - prev).abs();
            if d > std::f64::consts::PI {
                d = std::f64::consts::TAU - d;
            }
            if d.to_degrees() > crate::flock::problem::TURN_THRESHOLD_DEG {
                self.t += p.turn_penalty_s;
            }
        }
        self.heading = Some(h);
    }

    pub(super) fn fly(&mut self, p: &PhotoPlanner, pts: impl Iterator<Item = Point3>) {
        for q in pts {
            if let Some(a) = self.last {
                let (dx, dy, dz) = (q.x - a.x, q.y - a.y, q.z - a.z);
                self.turn_to(p, dy.atan2(dx), dx.hypot(dy));
                self.t += (dx * dx + dy * dy + dz * dz).sqrt() / p.speed_m_s;
            }
            self.last = Some(q);
        }
    }
}

fn round(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}

fn round3(p: [f64; 3]) -> [f64; 3] {
    [round(p[0]), round(p[1]), round(p[2])]
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn rays_match_the_oblique_footprint() {
        let cam = Camera::default();
        for pitch in [-90.0, -60.0, -45.0] {
            let pc = PhotoCamera::new(&cam, pitch);
            // Heading north: across = east, along = north.
            let rays = pc.rays(0.0);
            let want = crate::coverage::footprint_corners(&cam, 80.0, pitch).unwrap();
            for (r, w) in rays.iter().zip(want) {
                let g = flat_hit([0.0, 0.0, 80.0], *r, 0.0);
                assert_relative_eq!(g[0], w[0], epsilon = 1e-9);
                assert_relative_eq!(g[1], w[1], epsilon = 1e-9);
            }
            // Heading east: the same footprint turned by 90°.
            let g = flat_hit([0.0, 0.0, 80.0], pc.rays(90.0)[2], 0.0);
            let w = crate::coverage::footprint_corners(&cam, 80.0, pitch).unwrap()[2];
            assert_relative_eq!(g[0], w[1], epsilon = 1e-9);
            assert_relative_eq!(g[1], -w[0], epsilon = 1e-9);
        }
        // The nadir GSD: 2.74 cm/px at 100 m.
        let pc = PhotoCamera::new(&cam, -90.0);
        let want = 100.0 * 13.2 * 100.0 / (5472.0 * 8.8);
        assert_relative_eq!(pc.gsd_cm_px_per_m * 100.0, want, max_relative = 1e-12);
    }
}
