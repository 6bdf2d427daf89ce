//! GeoKeys: the CRS a GeoKeyDirectory declares (read) and the directory
//! that declares a CRS (written).

use super::ifd::Ifd;
use super::invalid;
use super::tags::*;
use crate::terrain::{Crs, TerrainError};

/// A parsed GeoKeyDirectory.
pub(super) struct GeoKeys {
    shorts: Vec<(u16, u16)>,
}

impl GeoKeys {
    pub(super) fn parse(ifd: &Ifd) -> Result<Option<GeoKeys>, TerrainError> {
        let Some(dir) = ifd.uints(GEO_KEY_DIRECTORY)? else {
            return Ok(None);
        };
        let bad = || invalid("the TIFF's GeoKeyDirectory is corrupt");
        let n = usize::try_from(*dir.get(3).ok_or_else(bad)?).map_err(|_| bad())?;
        let mut shorts = Vec::new();
        for i in 0..n {
            let k = dir.get(4 + 4 * i..8 + 4 * i).ok_or_else(bad)?;
            let (id, loc, _count, value) = match k {
                [a, b, c, d] => (*a, *b, *c, *d),
                _ => return Err(bad()),
            };
            // Only keys stored in the directory itself matter for the CRS.
            if loc == 0 {
                let (Ok(id), Ok(value)) = (u16::try_from(id), u16::try_from(value)) else {
                    return Err(bad());
                };
                shorts.push((id, value));
            }
        }
        Ok(Some(GeoKeys { shorts }))
    }

    pub(super) fn short(&self, id: u16) -> Option<u16> {
        self.shorts.iter().find(|(k, _)| *k == id).map(|(_, v)| *v)
    }

    /// The horizontal EPSG code, or why there is none.
    pub(super) fn epsg(&self) -> Result<u32, String> {
        let pcs = self.short(PROJECTED_CS_TYPE);
        let gcs = self.short(GEOGRAPHIC_TYPE);
        match self.short(GT_MODEL_TYPE) {
            Some(1) => self.projected(),
            Some(2) => self.geographic(),
            Some(3) => Err("the GeoKeys declare a geocentric model (GTModelTypeGeoKey=3)".into()),
            Some(0) | None if pcs.is_some() => self.projected(),
            Some(0) | None if gcs.is_some() => self.geographic(),
            None => Err(
                "the GeoKeys declare no model type, projected or geographic CRS (GDAL reads \
                 such a file as a local engineering CRS)"
                    .into(),
            ),
            Some(m) => Err(format!(
                "the GeoKeys declare an unknown model type (GTModelTypeGeoKey={m})"
            )),
        }
    }

    pub(super) fn projected(&self) -> Result<u32, String> {
        match self.short(PROJECTED_CS_TYPE) {
            Some(code) if code != USER_DEFINED && code != 0 => Ok(u32::from(code)),
            _ => {
                // User-defined: a UTM zone from ProjectionGeoKey and the datum.
                let Some(proj) = self.short(PROJECTION) else {
                    return Err(
                        "the projected CRS is user-defined (ProjectedCSTypeGeoKey=32767 or \
                         absent) without a ProjectionGeoKey"
                            .into(),
                    );
                };
                let (zone, north) = match proj {
                    16001..=16060 => (proj - 16000, true),
                    16101..=16160 => (proj - 16100, false),
                    _ => {
                        return Err(format!(
                            "the projected CRS is user-defined with ProjectionGeoKey={proj}, \
                             which is not a UTM zone"
                        ));
                    }
                };
                let geog = self.geographic()?;
                let zone = u32::from(zone);
                let code = match (geog, north) {
                    (4326, true) => 32600 + zone,
                    (4326, false) => 32700 + zone,
                    (4322, true) => 32200 + zone,
                    (4322, false) => 32300 + zone,
                    (4269, true) if (1..=23).contains(&zone) => 26900 + zone,
                    (4267, true) if (1..=22).contains(&zone) => 26700 + zone,
                    (4258, true) if (28..=38).contains(&zone) => 25800 + zone,
                    _ => {
                        return Err(format!(
                            "the projected CRS is UTM zone {zone}{} on EPSG:{geog}, which has \
                             no EPSG code terraplan knows",
                            if north { "N" } else { "S" }
                        ));
                    }
                };
                Ok(code)
            }
        }
    }

    pub(super) fn geographic(&self) -> Result<u32, String> {
        match self.short(GEOGRAPHIC_TYPE) {
            Some(code) if code != USER_DEFINED && code != 0 => Ok(u32::from(code)),
            _ => match self.short(GEOG_GEODETIC_DATUM) {
                Some(6326) => Ok(4326),
                Some(6269) => Ok(4269),
                Some(6267) => Ok(4267),
                Some(6258) => Ok(4258),
                Some(6322) => Ok(4322),
                Some(d) => Err(format!(
                    "the geographic CRS is user-defined with datum {d} (GeogGeodeticDatumGeoKey), \
                     which has no EPSG code terraplan knows"
                )),
                None => Err(
                    "the geographic CRS is user-defined (GeographicTypeGeoKey=32767 or absent) \
                     without a known datum"
                        .into(),
                ),
            },
        }
    }
}

/// The CRS code as a GeoKey value (SHORT; 32767 means user-defined).
pub(super) fn epsg_code(crs: &Crs) -> Option<u16> {
    u16::try_from(crs.epsg)
        .ok()
        .filter(|&c| c != 0 && c != USER_DEFINED)
}

/// The GeoKeyDirectory (version 1.1.0) declaring `crs`, whose GeoKey code
/// is `code` (see [`epsg_code`]), and the GeoAsciiParams it refers to;
/// `None` when the CRS name is too long for a GeoKey's count.
pub(super) fn directory(crs: &Crs, code: u16) -> Option<(Vec<u16>, Option<String>)> {
    let citation: String = crs
        .name
        .chars()
        .filter(|c| c.is_ascii() && !c.is_ascii_control() && *c != '|')
        .collect();
    let citation = citation.trim();
    // (key, location, count, value)
    let mut keys: Vec<[u16; 4]> = vec![
        [GT_MODEL_TYPE, 0, 1, if crs.geographic { 2 } else { 1 }],
        // PixelIsArea.
        [GT_RASTER_TYPE, 0, 1, 1],
    ];
    let ascii = if citation.is_empty() {
        None
    } else {
        // Strings in GeoAsciiParams end with '|', which the count includes.
        let text = format!("{citation}|");
        let count = u16::try_from(text.len()).ok()?;
        keys.push([GT_CITATION, GEO_ASCII_PARAMS, count, 0]);
        Some(text)
    };
    keys.push(if crs.geographic {
        [GEOGRAPHIC_TYPE, 0, 1, code]
    } else {
        [PROJECTED_CS_TYPE, 0, 1, code]
    });
    // Three or four keys.
    let mut dir = vec![1, 1, 0, keys.len() as u16];
    dir.extend(keys.iter().flatten());
    Some((dir, ascii))
}

/// The GeoKeyDirectory (as SHORTs) and GeoAsciiParams declaring `crs`, as
/// this module's writer writes them, for a GeoTIFF written elsewhere (the
/// service's streamed tiled download); `None` when its EPSG code does not
/// fit a GeoKey or its name is too long.
pub fn geokey_directory(crs: &Crs) -> Option<(Vec<u16>, Option<String>)> {
    directory(crs, epsg_code(crs)?)
}
