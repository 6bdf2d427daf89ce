//! `GET /api/v1/dems/{id}/dem.tif`: a stored DEM as a tiled GeoTIFF
//! assembled from its stored tiles and streamed a tile at a time (the
//! download holds one tile, whatever the DEM's size).
//!
//! The file is a BigTIFF (any size) of uncompressed 512² tiles, Float32 or
//! Float64 as the tiles are stored, NaN nodata (`GDAL_NODATA` "nan"), in
//! the DEM's CRS: every tile's size is known before the first is read, so
//! the header with all offsets comes first and `Content-Length` is exact.
//! A DEM stored before tiles is sent as the file that was uploaded.

use axum::extract::{Path, State};
use axum::http::{HeaderValue, header};
use axum::response::{IntoResponse, Response};
use planner_core::terrain::RasterGrid;
use planner_core::terrain::geotiff::geokey_directory;

use super::model::{BinaryFile, stored_info, visible_dem};
use crate::auth::{Caller, Role};
use crate::db::{Db, StoredFile};
use crate::error::{ApiError, Problem};
use crate::state::AppState;
use crate::state::dem_store::tiles::{self, TileSample, TileSet, decode_tile};

/// The stored DEM as a tiled GeoTIFF (BigTIFF, uncompressed 512² tiles,
/// Float32 or Float64 as stored, NaN nodata), streamed; a DEM stored
/// before tiles existed is sent as uploaded.
#[utoipa::path(
    get,
    path = "/api/v1/dems/{id}/dem.tif",
    tag = "dems",
    params(("id" = String, Path, description = "DEM id")),
    responses(
        (status = 200, description = "The GeoTIFF", content_type = "image/tiff", body = BinaryFile),
        (status = 404, description = "No such DEM", body = Problem, content_type = "application/problem+json"),
    )
)]
pub async fn download_dem(
    State(state): State<AppState>,
    caller: Caller,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let row = visible_dem(&state, &caller, &id, Role::Viewer).await?;
    let info = stored_info(&row)?;
    let Some((set, grid)) = tiles::stored_set(&state.db, &id, &info).await? else {
        let chunks = state
            .db
            .file_chunks(StoredFile::Dem(id.clone()), row.size_bytes);
        let mut res = axum::body::Body::from_stream(chunks).into_response();
        res.headers_mut()
            .insert(header::CONTENT_LENGTH, HeaderValue::from(row.size_bytes));
        res.headers_mut().insert(
            header::CONTENT_TYPE,
            HeaderValue::from_static("application/octet-stream"),
        );
        return Ok(res);
    };
    let head = tiff_head(&set, &grid)?;
    let (across, down) = set.tiles(0);
    let tile_bytes = (set.tile_side * set.tile_side * set.sample.bytes()) as u64;
    let total = head.len() as u64 + (across * down) as u64 * tile_bytes;
    let body = futures_util::stream::try_unfold(
        (Some(head), state.db.clone(), id, set, 0usize),
        |(head, db, id, set, next)| async move {
            if let Some(head) = head {
                return Ok::<_, ApiError>(Some((head, (None, db, id, set, next))));
            }
            let (across, down) = set.tiles(0);
            if next >= across * down {
                return Ok(None);
            }
            let bytes = padded_tile(&db, &id, &set, next % across, next / across).await?;
            Ok(Some((bytes, (None, db, id, set, next + 1))))
        },
    );
    let mut res =
        axum::body::Body::from_stream(futures_util::TryStreamExt::map_err(body, |e: ApiError| {
            std::io::Error::other(e.to_string())
        }))
        .into_response();
    res.headers_mut()
        .insert(header::CONTENT_TYPE, HeaderValue::from_static("image/tiff"));
    res.headers_mut()
        .insert(header::CONTENT_LENGTH, HeaderValue::from(total));
    Ok(res)
}

/// Tile (`col`, `row`) of level 0 as the file's samples: padded to a whole
/// tile with NaN, little-endian.
async fn padded_tile(
    db: &Db,
    id: &str,
    set: &TileSet,
    col: usize,
    row: usize,
) -> Result<Vec<u8>, ApiError> {
    let data = db
        .dem_tile(id, 0, row as i64, col as i64)
        .await?
        .ok_or_else(|| ApiError::Internal(format!("tile ({col}, {row}) of DEM {id} is missing")))?;
    let (cw, ch) = set.tile_size(0, col, row);
    let cells = decode_tile(&data, cw, ch, set.sample)
        .map_err(|e| ApiError::Internal(format!("DEM {id}: {e}")))?;
    let side = set.tile_side;
    let mut out = Vec::with_capacity(side * side * set.sample.bytes());
    for y in 0..side {
        for x in 0..side {
            let v = if x < cw && y < ch {
                cells[y * cw + x]
            } else {
                f64::NAN
            };
            match set.sample {
                TileSample::F32 => out.extend_from_slice(&(v as f32).to_le_bytes()),
                TileSample::F64 => out.extend_from_slice(&v.to_le_bytes()),
            }
        }
    }
    Ok(out)
}

/// One IFD entry of a BigTIFF: tag, type, count, value bytes.
struct Entry {
    tag: u16,
    typ: u16,
    count: u64,
    bytes: Vec<u8>,
}

fn shorts(tag: u16, v: &[u16]) -> Entry {
    Entry {
        tag,
        typ: 3,
        count: v.len() as u64,
        bytes: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
    }
}

fn longs(tag: u16, v: &[u32]) -> Entry {
    Entry {
        tag,
        typ: 4,
        count: v.len() as u64,
        bytes: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
    }
}

fn long8s(tag: u16, v: &[u64]) -> Entry {
    Entry {
        tag,
        typ: 16,
        count: v.len() as u64,
        bytes: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
    }
}

fn doubles(tag: u16, v: &[f64]) -> Entry {
    Entry {
        tag,
        typ: 12,
        count: v.len() as u64,
        bytes: v.iter().flat_map(|x| x.to_le_bytes()).collect(),
    }
}

fn ascii(tag: u16, text: &str) -> Entry {
    let mut bytes = text.as_bytes().to_vec();
    bytes.push(0);
    Entry {
        tag,
        typ: 2,
        count: bytes.len() as u64,
        bytes,
    }
}

/// The BigTIFF header, IFD and tag values of the tiled file of `set`'s
/// level 0 over `grid`; its tiles follow, row by row of tiles, each a
/// whole tile of samples.
fn tiff_head(set: &TileSet, grid: &RasterGrid) -> Result<Vec<u8>, ApiError> {
    let internal = |m: &str| ApiError::Internal(format!("cannot describe the DEM as GeoTIFF: {m}"));
    let (across, down) = set.tiles(0);
    let n = across * down;
    let side = set.tile_side as u32;
    let tile_bytes = u64::from(side) * u64::from(side) * set.sample.bytes() as u64;
    let width = u32::try_from(grid.width).map_err(|_| internal("too wide"))?;
    let height = u32::try_from(grid.height).map_err(|_| internal("too high"))?;
    let t = grid.transform;
    let (keys, citation) = geokey_directory(&grid.crs).ok_or_else(|| internal("its CRS"))?;
    let bits = (set.sample.bytes() * 8) as u16;
    let mut entries = vec![
        longs(256, &[width]),
        longs(257, &[height]),
        shorts(258, &[bits]),
        shorts(259, &[1]),
        shorts(262, &[1]),
        shorts(277, &[1]),
        shorts(284, &[1]),
        longs(322, &[side]),
        longs(323, &[side]),
        // Offsets filled in below, once the header's length is known.
        long8s(324, &vec![0; n]),
        long8s(325, &vec![tile_bytes; n]),
        shorts(339, &[3]),
    ];
    if t.row_rotation == 0.0 && t.col_rotation == 0.0 && t.pixel_height < 0.0 {
        entries.push(doubles(33550, &[t.pixel_width, -t.pixel_height, 0.0]));
        entries.push(doubles(
            33922,
            &[0.0, 0.0, 0.0, t.origin_x, t.origin_y, 0.0],
        ));
    } else {
        #[rustfmt::skip]
        let matrix = [
            t.pixel_width, t.row_rotation, 0.0, t.origin_x,
            t.col_rotation, t.pixel_height, 0.0, t.origin_y,
            0.0, 0.0, 0.0, 0.0,
            0.0, 0.0, 0.0, 1.0,
        ];
        entries.push(doubles(34264, &matrix));
    }
    entries.push(shorts(34735, &keys));
    if let Some(c) = citation {
        entries.push(ascii(34737, &c));
    }
    entries.push(ascii(42113, "nan"));
    entries.sort_by_key(|e| e.tag);

    // Header (16), IFD (8 + 20 per entry + 8), then the values that do
    // not fit in an entry, then the tiles.
    let ifd_len = 8 + 20 * entries.len() as u64 + 8;
    // Values start 8-aligned (each padded to 8 bytes).
    let mut data_at = (16 + ifd_len).next_multiple_of(8);
    let mut places = Vec::with_capacity(entries.len());
    for e in &entries {
        if e.bytes.len() > 8 {
            places.push(Some(data_at));
            data_at += (e.bytes.len() as u64).next_multiple_of(8);
        } else {
            places.push(None);
        }
    }
    let first_tile = data_at;
    let offsets: Vec<u64> = (0..n as u64).map(|i| first_tile + i * tile_bytes).collect();
    if let Some(e) = entries.iter_mut().find(|e| e.tag == 324) {
        e.bytes = offsets.iter().flat_map(|x| x.to_le_bytes()).collect();
    }

    let mut out = Vec::with_capacity(first_tile as usize);
    out.extend_from_slice(b"II");
    out.extend_from_slice(&43u16.to_le_bytes());
    out.extend_from_slice(&8u16.to_le_bytes());
    out.extend_from_slice(&0u16.to_le_bytes());
    out.extend_from_slice(&16u64.to_le_bytes());
    out.extend_from_slice(&(entries.len() as u64).to_le_bytes());
    for (e, place) in entries.iter().zip(&places) {
        out.extend_from_slice(&e.tag.to_le_bytes());
        out.extend_from_slice(&e.typ.to_le_bytes());
        out.extend_from_slice(&e.count.to_le_bytes());
        match place {
            Some(at) => out.extend_from_slice(&at.to_le_bytes()),
            None => {
                let mut field = e.bytes.clone();
                field.resize(8, 0);
                out.extend_from_slice(&field);
            }
        }
    }
    out.extend_from_slice(&0u64.to_le_bytes());
    out.resize(out.len().next_multiple_of(8), 0);
    for (e, place) in entries.iter().zip(&places) {
        if place.is_some() {
            out.extend_from_slice(&e.bytes);
            out.resize(out.len().next_multiple_of(8), 0);
        }
    }
    if out.len() as u64 != first_tile {
        return Err(internal("its header's length"));
    }
    Ok(out)
}
