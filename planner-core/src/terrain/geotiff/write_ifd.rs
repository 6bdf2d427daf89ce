//! The writer's image file directories: each page's entries (size,
//! strips, sample type, georeferencing, GeoKeys, GDAL metadata and nodata)
//! encoded little-endian and laid out with their out-of-line values.

use std::io;

use super::geokeys::{directory, epsg_code};
use super::raster::{Band, Page, Raster, Strips, invalid_input, len_u64, page_sample, too_large};
use super::tags::*;
use crate::xml::xml_escape;

/// One IFD entry with its value already little-endian encoded.
pub(super) struct Entry {
    pub(super) tag: u16,
    kind: u16,
    count: u64,
    bytes: Vec<u8>,
}

impl Entry {
    pub(super) fn shorts(tag: u16, values: &[u16]) -> Entry {
        Entry {
            tag,
            kind: SHORT,
            count: values.len() as u64,
            bytes: values.iter().flat_map(|v| v.to_le_bytes()).collect(),
        }
    }

    pub(super) fn long(tag: u16, value: u32) -> Entry {
        Entry {
            tag,
            kind: LONG,
            count: 1,
            bytes: value.to_le_bytes().to_vec(),
        }
    }

    /// LONG values in a classic TIFF, LONG8 in a BigTIFF.
    pub(super) fn offsets(tag: u16, values: &[u64], big: bool) -> io::Result<Entry> {
        let bytes = if big {
            values.iter().flat_map(|v| v.to_le_bytes()).collect()
        } else {
            let mut bytes = Vec::with_capacity(values.len() * 4);
            for &v in values {
                let v = u32::try_from(v).map_err(|_| too_large())?;
                bytes.extend_from_slice(&v.to_le_bytes());
            }
            bytes
        };
        Ok(Entry {
            tag,
            kind: if big { LONG8 } else { LONG },
            count: len_u64(values.len())?,
            bytes,
        })
    }

    fn doubles(tag: u16, values: &[f64]) -> Entry {
        Entry {
            tag,
            kind: DOUBLE,
            count: values.len() as u64,
            bytes: values.iter().flat_map(|v| v.to_le_bytes()).collect(),
        }
    }

    /// NUL-terminated text (the text itself must not contain NUL).
    fn ascii(tag: u16, text: &str) -> Entry {
        let mut bytes = text.as_bytes().to_vec();
        bytes.push(0);
        Entry {
            tag,
            kind: ASCII,
            count: bytes.len() as u64,
            bytes,
        }
    }
}

/// The IFD entries of `page`, sorted by tag, for its image data starting
/// at byte `data_start`.
pub(super) fn ifd_entries(
    r: &Raster<'_>,
    page: &Page<'_>,
    strips: &Strips,
    data_start: u64,
    big: bool,
) -> io::Result<Vec<Entry>> {
    let n = page.bands.len();
    let height = r.height;
    let dim = |v: usize| u32::try_from(v).map_err(|_| too_large());

    let mut offsets = Vec::with_capacity(n * strips.per_band);
    let mut counts = Vec::with_capacity(n * strips.per_band);
    let mut band_start = data_start;
    for _ in 0..n {
        for s in 0..strips.per_band {
            let rows = strips.rows(s, height);
            let first = len_u64(rows.start)? * strips.row_bytes;
            offsets.push(band_start + first);
            counts.push(len_u64(rows.len())? * strips.row_bytes);
        }
        band_start += strips.band_bytes;
    }

    let mut entries = vec![
        Entry::offsets(STRIP_OFFSETS, &offsets, big)?,
        Entry::long(ROWS_PER_STRIP, dim(strips.rows_per_strip)?),
        Entry::offsets(STRIP_BYTE_COUNTS, &counts, big)?,
    ];
    entries.extend(image_entries(r, page)?);
    entries.sort_by_key(|e| e.tag);
    Ok(entries)
}

/// The entries of a page whatever its layout (strips or tiles): size,
/// sample type, planes, georeferencing, GeoKeys, GDAL metadata and
/// nodata; unsorted.
pub(super) fn image_entries(r: &Raster<'_>, page: &Page<'_>) -> io::Result<Vec<Entry>> {
    let n = page.bands.len();
    let samples = u16::try_from(n).map_err(|_| too_large())?;
    let dim = |v: usize| u32::try_from(v).map_err(|_| too_large());
    let (bits, format) = page_sample(page).tiff_tags();
    let mut entries = vec![
        Entry::long(IMAGE_WIDTH, dim(r.width)?),
        Entry::long(IMAGE_LENGTH, dim(r.height)?),
        Entry::shorts(BITS_PER_SAMPLE, &vec![bits; n]),
        // No compression.
        Entry::shorts(COMPRESSION, &[1]),
        // BlackIsZero.
        Entry::shorts(PHOTOMETRIC, &[1]),
        Entry::shorts(SAMPLES_PER_PIXEL, &[samples]),
        // Separate planes.
        Entry::shorts(PLANAR_CONFIG, &[2]),
        Entry::shorts(SAMPLE_FORMAT, &vec![format; n]),
    ];
    if n > 1 {
        // The bands after the first are unspecified extra samples, as GDAL
        // writes them (libtiff warns otherwise).
        entries.push(Entry::shorts(EXTRA_SAMPLES, &vec![0; n - 1]));
    }

    let t = r.transform;
    if t.row_rotation == 0.0 && t.col_rotation == 0.0 && t.pixel_width > 0.0 && t.pixel_height < 0.0
    {
        entries.push(Entry::doubles(
            MODEL_PIXEL_SCALE,
            &[t.pixel_width, -t.pixel_height, 0.0],
        ));
        entries.push(Entry::doubles(
            MODEL_TIEPOINT,
            &[0.0, 0.0, 0.0, t.origin_x, t.origin_y, 0.0],
        ));
    } else {
        // Rotated, sheared or flipped: ModelPixelScale cannot say it.
        #[rustfmt::skip]
        let matrix = [
            t.pixel_width, t.row_rotation, 0.0, t.origin_x,
            t.col_rotation, t.pixel_height, 0.0, t.origin_y,
            0.0, 0.0, 0.0, 0.0,
            0.0, 0.0, 0.0, 1.0,
        ];
        entries.push(Entry::doubles(MODEL_TRANSFORMATION, &matrix));
    }

    let code = epsg_code(r.crs).ok_or_else(|| invalid_input("bad EPSG code"))?;
    let (keys, ascii) = directory(r.crs, code).ok_or_else(|| invalid_input("CRS name too long"))?;
    entries.push(Entry::shorts(GEO_KEY_DIRECTORY, &keys));
    if let Some(ascii) = ascii {
        entries.push(Entry::ascii(GEO_ASCII_PARAMS, &ascii));
    }
    if let Some(xml) = gdal_metadata(page.bands) {
        entries.push(Entry::ascii(GDAL_METADATA, &xml));
    }
    if let Some(v) = page.nodata {
        entries.push(Entry::ascii(GDAL_NODATA, &format_nodata(v)));
    }
    Ok(entries)
}

/// `GDAL_METADATA` holding the bands' metadata items, descriptions and
/// units (the non-empty ones), as GDAL writes them: `sample` is the band's
/// index (from 0) on its page, and the `description` and `unittype` roles
/// are what GDAL's `GetDescription()` and `GetUnitType()` return.
pub(super) fn gdal_metadata(bands: &[Band<'_>]) -> Option<String> {
    let mut xml = String::from("<GDALMetadata>\n");
    let mut any = false;
    for (i, band) in bands.iter().enumerate() {
        for (name, value) in band.metadata {
            any = true;
            xml.push_str(&format!(
                "  <Item name=\"{name}\" sample=\"{i}\">{}</Item>\n",
                xml_escape(value)
            ));
        }
        for (name, role, text) in [
            ("DESCRIPTION", "description", band.description),
            ("UNITTYPE", "unittype", band.unit),
        ] {
            let text = xml_escape(text);
            if text.is_empty() {
                continue;
            }
            any = true;
            xml.push_str(&format!(
                "  <Item name=\"{name}\" sample=\"{i}\" role=\"{role}\">{text}</Item>\n"
            ));
        }
    }
    xml.push_str("</GDALMetadata>");
    any.then_some(xml)
}

/// The `GDAL_NODATA` text: `nan`, `inf`, `-inf` as GDAL writes them,
/// otherwise the shortest decimal that reads back as exactly `v`.
pub(super) fn format_nodata(v: f64) -> String {
    if v.is_nan() {
        "nan".to_string()
    } else if v.is_infinite() {
        if v > 0.0 { "inf" } else { "-inf" }.to_string()
    } else if v != 0.0 && !(1e-4..1e16).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// The IFD (entry table, the next-IFD pointer `next`, then the values
/// that do not fit an entry, 8-byte aligned) for an IFD at byte
/// `ifd_offset`.
pub(super) fn serialize_ifd(
    entries: &[Entry],
    big: bool,
    ifd_offset: u64,
    next: u64,
) -> io::Result<Vec<u8>> {
    let (count_len, entry_len, inline) = if big { (8, 20, 8) } else { (2, 12, 4) };
    let next_len = inline;
    let table_len = count_len + entries.len() * entry_len + next_len;
    let mut table = Vec::with_capacity(table_len);
    let mut values: Vec<u8> = Vec::new();
    let put = |buf: &mut Vec<u8>, v: u64| -> io::Result<()> {
        if big {
            buf.extend_from_slice(&v.to_le_bytes());
        } else {
            let v = u32::try_from(v).map_err(|_| too_large())?;
            buf.extend_from_slice(&v.to_le_bytes());
        }
        Ok(())
    };
    let n = len_u64(entries.len())?;
    if big {
        table.extend_from_slice(&n.to_le_bytes());
    } else {
        let n = u16::try_from(n).map_err(|_| too_large())?;
        table.extend_from_slice(&n.to_le_bytes());
    }
    let values_start = ifd_offset + len_u64(table_len)?;
    for e in entries {
        table.extend_from_slice(&e.tag.to_le_bytes());
        table.extend_from_slice(&e.kind.to_le_bytes());
        put(&mut table, e.count)?;
        if e.bytes.len() <= inline {
            table.extend_from_slice(&e.bytes);
            table.resize(table.len() + inline - e.bytes.len(), 0);
        } else {
            let misalign = (values_start + len_u64(values.len())?) % 8;
            if misalign != 0 {
                values.resize(values.len() + (8 - misalign) as usize, 0);
            }
            put(&mut table, values_start + len_u64(values.len())?)?;
            values.extend_from_slice(&e.bytes);
        }
    }
    put(&mut table, next)?;
    debug_assert_eq!(table.len(), table_len);
    table.extend_from_slice(&values);
    Ok(table)
}
