//! `photos.geojson`: a UAV's planned photos as GeoJSON, one Feature per
//! photo — its footprint Polygon on the ground, the camera's position,
//! time since take-off, pitch, heading, cell and GSD as properties.

use std::fmt::Write;

use super::files::PlanFile;
use super::photos::{Photo, SortiePhotos};
use super::result::{SortiePlan, SurveyPlan};
use crate::geo::{GeoError, UtmProjection};

/// Suffix of the photos file, after `<uav id>.` (all its sorties) or
/// `<sortie stem>.` (that sortie's).
pub(super) const PHOTOS_FILE_SUFFIX: &str = "photos.geojson";

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
            content,
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
        let over_dem = sorties.iter().any(|(_, s)| s.terrain.is_some());
        let reference = if over_dem {
            "the DEM's vertical datum (above mean sea level for an orthometric DEM)"
        } else {
            "above the take-off point (the footprints on level ground at its height)"
        };
        let uav_json = serde_json::to_string(uav).unwrap_or_default();
        let mut out = String::from("{\"type\": \"FeatureCollection\", \"features\": [");
        let mut first = true;
        for (k, sortie) in sorties {
            let Some(photos) = &sortie.photos else {
                continue;
            };
            for (index, p) in photos.photos().enumerate() {
                out.push_str(if first { "\n" } else { ",\n" });
                first = false;
                feature(&mut out, &proj, photos, &p, &uav_json, k + 1, index)?;
            }
        }
        let _ = write!(
            out,
            "\n], \"properties\": {{\"uav\": {uav_json}, \"altitude_reference\": \"{reference}\", \
             \"utm_epsg\": {epsg}}}}}\n"
        );
        Ok(out)
    }
}

/// One photo's Feature, written to `out`: its footprint's corners (near
/// left, near right, far right, far left, closed) as the Polygon.
fn feature(
    out: &mut String,
    proj: &UtmProjection,
    photos: &SortiePhotos,
    p: &Photo,
    uav_json: &str,
    sortie: usize,
    index: usize,
) -> Result<(), GeoError> {
    let ll = |c: &[f64; 3]| proj.to_wgs84(geo_types::Coord { x: c[0], y: c[1] });
    out.push_str(
        "{\"type\": \"Feature\", \"geometry\": {\"type\": \"Polygon\", \"coordinates\": [[",
    );
    for (n, i) in [0, 1, 2, 3, 0].into_iter().enumerate() {
        let c = ll(&p.corners[i])?;
        let sep = if n == 0 { "" } else { ", " };
        let _ = write!(out, "{sep}[{:.8}, {:.8}]", c.x, c.y);
    }
    let camera = ll(&p.camera)?;
    let centre = ll(&p.centre)?;
    let _ = write!(
        out,
        "]]}}, \"properties\": {{\"uav\": {uav_json}, \"sortie\": {sortie}, \"index\": {index}, \
         \"cell\": {}, \"time_s\": {:.2}, \"camera_pitch_deg\": {}, \"heading_deg\": {:.3}, \
         \"centre\": [{:.8}, {:.8}, {:.3}], \"ground_centre\": [{:.8}, {:.8}], \
         \"ground_heights_m\": [{:.3}, {:.3}, {:.3}, {:.3}, {:.3}], \"gsd_cm_px\": {:.4}}}}}",
        p.cell,
        p.time_s,
        photos.camera.pitch_deg,
        p.heading_deg,
        camera.x,
        camera.y,
        p.camera[2],
        centre.x,
        centre.y,
        p.corners[0][2],
        p.corners[1][2],
        p.corners[2][2],
        p.corners[3][2],
        p.centre[2],
        p.gsd_cm_px(&photos.camera),
    );
    Ok(())
}
