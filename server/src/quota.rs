//! Storage quotas per project: the bytes it stores (`--project-quota-mb`),
//! and its costmap jobs waiting or running (`--project-queued-jobs`).
//! Checked before work is queued or a file is stored: over the bytes,
//! 413; over the jobs, 429.
//!
//! A project's stored bytes are its DEMs' tiles (compressed, overviews
//! included), the files kept with them (an ESRI grid's or `.hgt` file's,
//! and that of a DEM stored before tiles; a GeoTIFF's is not kept), the
//! tiles of its uploads still running, and its costmaps' files. An upload
//! is refused before its body is read when its declared size alone would
//! pass the quota, and while its tiles are stored, before the batch that
//! would pass it (what it stored is then removed).
//!
//! A costmap counts against the bytes by an estimate of its files when it
//! is asked for; the queued-jobs limit bounds how far estimates of jobs
//! still running can add up past the quota.

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::db::Db;
use crate::error::ApiError;
use crate::memory::mib;

/// How long a client whose project has too many jobs queued should wait.
const JOBS_RETRY_AFTER_S: u64 = 10;

/// The limits of every project (`None`: no limit).
#[derive(Clone, Copy, Debug)]
pub struct Quotas {
    pub bytes: Option<u64>,
    pub queued_jobs: Option<u64>,
}

/// A project's use of its quotas, as the project resource reports it.
#[derive(Debug, Serialize, Deserialize, ToSchema)]
pub struct Usage {
    /// Bytes the project stores: its DEMs' tiles and kept files, the
    /// tiles of its uploads running, its costmaps' files.
    pub stored_bytes: u64,
    /// `--project-quota-mb` in bytes; absent when there is no limit.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub quota_bytes: Option<u64>,
    /// Costmap jobs queued or running.
    pub queued_jobs: u64,
    /// `--project-queued-jobs`; absent when there is no limit.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_queued_jobs: Option<u64>,
}

impl Quotas {
    /// From the flags: 0 means no limit.
    pub fn new(quota_mb: u64, queued_jobs: u64) -> Quotas {
        Quotas {
            bytes: (quota_mb > 0).then(|| quota_mb.saturating_mul(1024 * 1024)),
            queued_jobs: (queued_jobs > 0).then_some(queued_jobs),
        }
    }

    /// A project's use of its quotas.
    pub async fn usage(&self, db: &Db, project_id: &str) -> Result<Usage, ApiError> {
        let (stored, queued) = db.project_usage(project_id).await?;
        Ok(Usage {
            stored_bytes: stored.max(0) as u64,
            quota_bytes: self.bytes,
            queued_jobs: queued.max(0) as u64,
            max_queued_jobs: self.queued_jobs,
        })
    }
}

impl Usage {
    /// 413 when storing `adding` more bytes (`what`) would take project
    /// `project_id` past its quota.
    pub fn check_bytes(&self, project_id: &str, adding: u64, what: &str) -> Result<(), ApiError> {
        let Some(quota) = self.quota_bytes else {
            return Ok(());
        };
        let after = self.stored_bytes.saturating_add(adding);
        if after > quota {
            return Err(ApiError::PayloadTooLarge(format!(
                "{what} ({}) would take project {project_id:?} to {} of its {} quota \
                 (--project-quota-mb): delete DEMs or costmaps first",
                mib(adding),
                mib(after),
                mib(quota)
            )));
        }
        Ok(())
    }

    /// 413 when storing `adding` more bytes of an upload's tiles (of
    /// which `so_far` are stored, and counted in the usage) would take
    /// project `project_id` past its quota.
    pub fn check_tiles(&self, project_id: &str, so_far: u64, adding: u64) -> Result<(), ApiError> {
        let Some(quota) = self.quota_bytes else {
            return Ok(());
        };
        let after = self.stored_bytes.saturating_add(adding);
        if after > quota {
            return Err(ApiError::PayloadTooLarge(format!(
                "the DEM's tiles ({} compressed so far, overviews included) would take project \
                 {project_id:?} past its {} quota (--project-quota-mb; {} stored without this \
                 upload): delete DEMs or costmaps first; nothing of this upload was kept",
                mib(so_far.saturating_add(adding)),
                mib(quota),
                mib(self.stored_bytes.saturating_sub(so_far)),
            )));
        }
        Ok(())
    }

    /// 429 when project `project_id` already has as many costmap jobs
    /// queued or running as it may.
    pub fn check_jobs(&self, project_id: &str) -> Result<(), ApiError> {
        let Some(max) = self.max_queued_jobs else {
            return Ok(());
        };
        if self.queued_jobs >= max {
            return Err(ApiError::TooManyRequests {
                message: format!(
                    "project {project_id:?} has {} costmap jobs queued or running, its \
                     limit (--project-queued-jobs): try again when one has finished",
                    self.queued_jobs
                ),
                retry_after_s: JOBS_RETRY_AFTER_S,
            });
        }
        Ok(())
    }
}

/// The files of a costmap of `cells` cells with `layers` extra layers, at
/// most: the cost (f32) and class (u8) bands, each layer as f32, and the
/// RGBA preview, uncompressed.
pub fn costmap_file_bytes(cells: u64, layers: u64) -> u64 {
    cells.saturating_mul(5 + 4 * layers + 4)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_means_no_limit() {
        let q = Quotas::new(0, 0);
        assert!(q.bytes.is_none() && q.queued_jobs.is_none());
        let q = Quotas::new(2, 3);
        assert_eq!(q.bytes, Some(2 * 1024 * 1024));
        assert_eq!(q.queued_jobs, Some(3));
    }

    #[test]
    fn tiles_past_the_quota_are_refused_naming_it() {
        let usage = Usage {
            stored_bytes: 900 * 1024,
            quota_bytes: Some(1024 * 1024),
            queued_jobs: 0,
            max_queued_jobs: None,
        };
        assert!(usage.check_tiles("p", 100 * 1024, 124 * 1024).is_ok());
        let e = usage
            .check_tiles("p", 100 * 1024, 124 * 1024 + 1)
            .unwrap_err();
        let ApiError::PayloadTooLarge(m) = e else {
            panic!("not a 413: {e:?}")
        };
        assert!(
            m.contains("--project-quota-mb") && m.contains("1.0 MiB quota"),
            "{m}"
        );
        assert!(m.contains("0.8 MiB stored without this upload"), "{m}");
        let unlimited = Usage {
            quota_bytes: None,
            ..usage
        };
        assert!(unlimited.check_tiles("p", 0, u64::MAX).is_ok());
    }

    #[test]
    fn a_costmap_estimate_grows_with_its_layers() {
        assert_eq!(costmap_file_bytes(1000, 0), 9000);
        assert_eq!(costmap_file_bytes(1000, 2), 17000);
        assert_eq!(costmap_file_bytes(u64::MAX, 3), u64::MAX);
    }
}
