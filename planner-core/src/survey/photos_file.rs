//! `photos.geojson`: a UAV's planned photos as GeoJSON, one Feature per
//! photo — its footprint Polygon on the ground, the camera's position,
//! time since take-off, pitch, heading, cell and GSD as properties — up to
//! a limit of features, beyond which every k-th photo is written and the
//! file says so.

use super::files::PlanFile;
use super::photos::{Photo, SortiePhotos};
use super::result::{SortiePlan, SurveyPlan};
use crate::geo::{GeoError, UtmProjection};

/// Suffix of the photos file, after `<uav id>.` (all its sorties) or
/// `<sortie stem>.` (that sortie's).
pub(super) const PHOTOS_FILE_SUFFIX: &str = "photos.geojson";

/// [`crate::geo::DEFAULT_MAX_PHOTO_FEATURES`], for serde's default.
pub(super) fn default_max_photo_features() -> usize {
    crate::geo::DEFAULT_MAX_PHOTO_FEATURES
}

impl SurveyPlan {
    /// Names of the photo files: `<uav>.photos.geojson` for each UAV whose
    /// photos were planned.
    pub(super) fn photo_file_names(&self) -> impl Iterator<Item = String> + '_ {
        self.uavs
            .iter()
            .filter(|u| u.sorties.iter().any(|s| s.photos.is_some()))
            .map(|u| format!("{}.{PHOTOS_FILE_SUFFIX}", u.id))
    }

    /// The photos file `name` names: a UAV's (every sortie) or one
    /// sortie's; `None` for another name or a UAV without planned photos.
    pub(super) fn photos_file(&self, name: &str) -> Option<PlanFile> {
        let stem = name.strip_suffix(PHOTOS_FILE_SUFFIX)?.strip_suffix('.')?;
        let (uav, sorties): (&str, Vec<(usize, &SortiePlan)>) = self.uavs.iter().find_map(|u| {
            if u.id == stem {
                return Some((u.id.as_str(), u.sorties.iter().enumerate().collect()));
            }
            let k = u.sorties.iter().position(|s| s.file_stem == stem)?;
            Some((u.id.as_str(), vec![(k, &u.sorties[k])]))
        })?;
        if sorties.iter().all(|(_, s)| s.photos.is_none()) {
            return None;
        }
        let content = self.render_photos(uav, &sorties).ok()?;
        Some(PlanFile {
            name: name.to_string(),
            content_type: "application/geo+json",
            content: content.into_bytes(),
        })
    }

    /// The FeatureCollection text of `sorties` (numbered from 0) of `uav`.
    fn render_photos(
        &self,
        uav: &str,
        sorties: &[(usize, &SortiePlan)],
    ) -> Result<String, GeoError> {
        let epsg = self.utm_epsg;
        let proj = UtmProjection::new((epsg % 100) as u8, epsg < 32700)?;
        let over_dem = sorties.iter().any(|(_, s)| {
            s.photos
                .as_ref()
                .is_some_and(|p| p.lanes.iter().any(|l| !l.ground.is_empty()))
        });
        let reference = if over_dem {
            "heights in the DEM's vertical datum (above mean sea level for an orthometric DEM)"
        } else {
            "heights above the take-off point; footprints on level ground at its height"
        };
        // Over the limit, every k-th photo (of all the file's sorties) is
        // written: the whole survey, thinned, in a bounded file.
        let total: usize = sorties
            .iter()
            .filter_map(|(_, s)| s.photos.as_ref())
            .flat_map(|p| &p.lanes)
            .map(|l| l.count)
            .sum();
        let limit = self.max_photo_features.max(1);
        let every = total.div_ceil(limit).max(1);
        let written = total.div_ceil(every);
        let mut out: Vec<u8> = Vec::with_capacity(written.min(limit) * 450 + 512);
        out.extend_from_slice(b"{\"type\":\"FeatureCollection\",\"properties\":{\"uav\":");
        json(&mut out, uav);
        out.extend_from_slice(b",\"heights\":");
        json(&mut out, reference);
        out.extend_from_slice(b",\"utm_epsg\":");
        json(&mut out, &epsg);
        if every > 1 {
            out.extend_from_slice(b",\"truncated\":true,\"photos\":");
            json(&mut out, &total);
            out.extend_from_slice(b",\"features\":");
            json(&mut out, &written);
            out.extend_from_slice(b",\"every_kth_photo\":");
            json(&mut out, &every);
            out.extend_from_slice(b",\"max_photo_features\":");
            json(&mut out, &limit);
            out.extend_from_slice(b",\"note\":");
            json(
                &mut out,
                &format!(
                    "the plan has {total} photos, more than the {limit} features this file may \
                     hold (max_photo_features): one photo in every {every} is written, each with its \
                     own sortie and index"
                ),
            );
        }
        out.extend_from_slice(b"},\"features\":[");
        let mut first = true;
        let mut seen = 0usize;
        for (k, sortie) in sorties {
            let Some(photos) = &sortie.photos else {
                continue;
            };
            for (index, p) in photos.photos().enumerate() {
                seen += 1;
                if !(seen - 1).is_multiple_of(every) {
                    continue;
                }
                out.extend_from_slice(if first { b"\n" } else { b",\n" });
                first = false;
                let place = Place {
                    sortie: k + 1,
                    index,
                    over_dem,
                };
                feature(&mut out, &proj, photos, &p, place)?;
            }
        }
        out.extend_from_slice(b"\n]}\n");
        Ok(String::from_utf8(out).unwrap_or_default())
    }
}

/// Where a photo is in the file: its sortie (from 1), its index in the
/// sortie, and whether heights of the ground are known.
struct Place {
    sortie: usize,
    index: usize,
    over_dem: bool,
}

/// One photo's Feature, written to `out`: its footprint's corners (near
/// left, near right, far right, far left, closed) as the Polygon; lon/lat to
/// 1e-7° (about a centimetre).
fn feature(
    out: &mut Vec<u8>,
    proj: &UtmProjection,
    photos: &SortiePhotos,
    p: &Photo,
    place: Place,
) -> Result<(), GeoError> {
    let ll = local_lonlat(proj, p.camera)?;
    let lonlat = |out: &mut Vec<u8>, c: &[f64; 3]| -> Result<(), GeoError> {
        let g = ll(c);
        out.push(b'[');
        num(out, g.x, 1e7);
        out.push(b',');
        num(out, g.y, 1e7);
        Ok(())
    };
    out.extend_from_slice(
        b"{\"type\":\"Feature\",\"geometry\":{\"type\":\"Polygon\",\"coordinates\":[[",
    );
    for (n, i) in [0, 1, 2, 3, 0].into_iter().enumerate() {
        if n > 0 {
            out.push(b',');
        }
        lonlat(out, &p.corners[i])?;
        out.push(b']');
    }
    out.extend_from_slice(b"]]},\"properties\":{\"sortie\":");
    json(out, &place.sortie);
    out.extend_from_slice(b",\"index\":");
    json(out, &place.index);
    out.extend_from_slice(b",\"lane\":");
    json(out, &p.lane);
    out.extend_from_slice(b",\"cell\":");
    json(out, &p.cell);
    out.extend_from_slice(b",\"time_s\":");
    num(out, p.time_s, 1e2);
    out.extend_from_slice(b",\"camera_pitch_deg\":");
    num(out, photos.camera.pitch_deg, 1e6);
    out.extend_from_slice(b",\"heading_deg\":");
    num(out, p.heading_deg, 1e4);
    out.extend_from_slice(b",\"centre\":");
    lonlat(out, &p.camera)?;
    out.push(b',');
    num(out, p.camera[2], 1e3);
    out.extend_from_slice(b"],\"ground_centre\":");
    lonlat(out, &p.centre)?;
    out.push(b']');
    if place.over_dem {
        out.extend_from_slice(b",\"ground_heights_m\":[");
        for (n, c) in p
            .corners
            .iter()
            .chain(std::iter::once(&p.centre))
            .enumerate()
        {
            if n > 0 {
                out.push(b',');
            }
            num(out, c[2], 1e3);
        }
        out.push(b']');
    }
    out.extend_from_slice(b",\"gsd_cm_px\":");
    num(out, p.gsd_cm_px(&photos.camera), 1e4);
    out.extend_from_slice(b"}}");
    Ok(())
}

/// lon/lat of points near `at` (UTM): PROJ at `at` and its derivatives
/// there (from two more points 1 m away), so a photo takes three
/// transformations instead of seven. Across a footprint of a few hundred
/// metres the neglected curvature of the projection is a few millimetres.
fn local_lonlat(
    proj: &UtmProjection,
    at: [f64; 3],
) -> Result<impl Fn(&[f64; 3]) -> geo_types::Coord<f64>, GeoError> {
    let c = |x: f64, y: f64| proj.to_wgs84(geo_types::Coord { x, y });
    let o = c(at[0], at[1])?;
    let dx = c(at[0] + 1.0, at[1])? - o;
    let dy = c(at[0], at[1] + 1.0)? - o;
    Ok(move |p: &[f64; 3]| {
        let (u, v) = (p[0] - at[0], p[1] - at[1]);
        o + dx * u + dy * v
    })
}

/// `v` rounded to `1/scale`, in its shortest form.
fn num(out: &mut Vec<u8>, v: f64, scale: f64) {
    json(out, &((v * scale).round() / scale));
}

fn json<T: serde::Serialize + ?Sized>(out: &mut Vec<u8>, v: &T) {
    // Writing to a Vec cannot fail; numbers and strings always serialize.
    let _ = serde_json::to_writer(&mut *out, v);
}
