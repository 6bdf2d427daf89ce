//! GeoPackages (SQLite): every feature table of `gpkg_geometry_columns`,
//! its CRS from `gpkg_spatial_ref_sys`, its geometry blobs read by
//! `planner_core::import::read_gpkg_geometry` and reprojected to WGS84.

use std::path::Path;

use planner_core::import::{ImportError, Imported, ToWgs84, read_gpkg_geometry};
use serde_json::{Map, Value};
use sqlx::sqlite::{SqliteConnectOptions, SqliteRow};
use sqlx::{Column, ConnectOptions, Row, SqliteConnection};

fn malformed(what: &str, e: impl std::fmt::Display) -> ImportError {
    ImportError::Malformed(format!("{what}: {e}"))
}

/// `name` quoted as an SQL identifier.
fn quote(name: &str) -> String {
    format!("\"{}\"", name.replace('"', "\"\""))
}

/// The features of the GeoPackage file at `path`, opened read-only.
pub async fn read_gpkg(path: &Path) -> Result<Imported, ImportError> {
    let mut conn = SqliteConnectOptions::new()
        .filename(path)
        .read_only(true)
        .immutable(true)
        .connect()
        .await
        .map_err(|e| malformed("not a readable SQLite file", e))?;
    let layers: Vec<(String, String, i64)> =
        sqlx::query_as("SELECT table_name, column_name, srs_id FROM gpkg_geometry_columns")
            .fetch_all(&mut conn)
            .await
            .map_err(|e| malformed("not a GeoPackage (no readable gpkg_geometry_columns)", e))?;
    if layers.is_empty() {
        return Err(ImportError::Malformed(
            "the GeoPackage has no feature table".into(),
        ));
    }
    let mut out = Imported::default();
    for (table, column, srs_id) in layers {
        let crs = crs_of(&mut conn, &table, srs_id).await?;
        // The table name comes from the file: quoted as an identifier, on
        // a read-only connection.
        let sql = sqlx::AssertSqlSafe(format!("SELECT * FROM {}", quote(&table)));
        let rows = sqlx::query(sql)
            .fetch_all(&mut conn)
            .await
            .map_err(|e| malformed(&format!("table {table:?} is unreadable"), e))?;
        // Made after the last await: a PROJ transformation stays on its
        // thread.
        let to_wgs84 = ToWgs84::from_definition(&crs)
            .map_err(|e| ImportError::Crs(format!("table {table:?}: {e}")))?;
        for (i, row) in rows.iter().enumerate() {
            let label = format!("table {table:?} row {i}");
            let blob: Option<Vec<u8>> = row
                .try_get(column.as_str())
                .map_err(|e| malformed(&format!("{label}: geometry column {column:?}"), e))?;
            let geometry = blob.as_deref().map(read_gpkg_geometry).transpose();
            match geometry {
                Ok(Some(Some(g))) => {
                    out.push(&label, to_wgs84.geometry(g), properties(row, &column))
                }
                Ok(_) => out.messages.push(format!("{label} skipped: no geometry")),
                Err(m) => out.messages.push(format!("{label} skipped: {m}")),
            }
        }
    }
    Ok(out)
}

/// The CRS `srs_id` names, for PROJ: `EPSG:<code>` or its WKT.
async fn crs_of(
    conn: &mut SqliteConnection,
    table: &str,
    srs_id: i64,
) -> Result<String, ImportError> {
    let row: Option<(String, i64, String)> = sqlx::query_as(
        "SELECT organization, organization_coordsys_id, definition FROM gpkg_spatial_ref_sys \
         WHERE srs_id = ?",
    )
    .bind(srs_id)
    .fetch_optional(&mut *conn)
    .await
    .map_err(|e| malformed("gpkg_spatial_ref_sys is unreadable", e))?;
    let Some((org, code, definition)) = row else {
        return Err(ImportError::Crs(format!(
            "table {table:?}: its srs_id {srs_id} is not in gpkg_spatial_ref_sys"
        )));
    };
    if srs_id <= 0 {
        return Err(ImportError::Crs(format!(
            "table {table:?} has an undefined CRS (srs_id {srs_id}): its coordinates cannot be \
             placed"
        )));
    }
    Ok(if org.eq_ignore_ascii_case("EPSG") && code > 0 {
        format!("EPSG:{code}")
    } else {
        definition
    })
}

/// The row's other columns that are numbers or text.
fn properties(row: &SqliteRow, geometry_column: &str) -> Map<String, Value> {
    let mut p = Map::new();
    for (i, col) in row.columns().iter().enumerate() {
        let name = col.name();
        if name == geometry_column {
            continue;
        }
        let v = if let Ok(v) = row.try_get::<Option<i64>, _>(i) {
            Value::from(v)
        } else if let Ok(v) = row.try_get::<Option<f64>, _>(i) {
            Value::from(v)
        } else if let Ok(v) = row.try_get::<Option<String>, _>(i) {
            Value::from(v)
        } else {
            continue;
        };
        p.insert(name.to_string(), v);
    }
    p
}

/// [`read_gpkg`] for synchronous callers (the CLI), on a runtime of its own.
pub fn read_gpkg_blocking(path: &Path) -> Result<Imported, ImportError> {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .map_err(|e| malformed("cannot start the GeoPackage reader", e))?
        .block_on(read_gpkg(path))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quotes_identifiers_and_refuses_non_geopackages() {
        assert_eq!(quote("a\"b"), "\"a\"\"b\"");
        let dir = std::env::temp_dir().join(format!("tp-gpkg-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("x.gpkg");
        std::fs::write(&path, b"not sqlite at all").unwrap();
        let e = read_gpkg_blocking(&path).unwrap_err();
        assert!(e.to_string().starts_with("not a"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
