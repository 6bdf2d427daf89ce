//! Notes about costmap jobs between the processes that share a database:
//! a job's status and progress as its holder reports them, so that event
//! streams on every replica follow it live and idle replicas take over a
//! job given back at once rather than at their next maintenance round.
//!
//! On PostgreSQL a note is a `NOTIFY` on one channel, which every process
//! (the sender included) receives through its own `LISTEN` connection; on
//! SQLite the database is one process' alone, so a note goes straight to
//! that process' subscribers. Notes are a fast path only: they are lost
//! while a listener is reconnecting, so whoever follows them also reads
//! the job table now and then.

use std::time::Duration;

use planner_core::costmap::Stage;
use serde::{Deserialize, Serialize};
use sqlx::postgres::PgListener;
use tokio::sync::broadcast;

use super::record::JobStatus;
use crate::db::Db;

/// The PostgreSQL channel of the notes.
const CHANNEL: &str = "terraplan_costmap_jobs";
/// Notes kept for a subscriber that has not read them yet; one that
/// falls further behind skips to the newest (and reads the table).
const BACKLOG: usize = 1024;
/// Wait before listening again after the connection was lost.
const RECONNECT_AFTER: Duration = Duration::from_secs(1);

/// What a job's holder reports: where the job stands now.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct JobNote {
    pub id: String,
    pub status: JobStatus,
    /// [0, 1].
    pub progress: f64,
    pub stage: Option<Stage>,
}

/// This process' end of the notes.
pub(super) struct Feed {
    db: Db,
    tx: broadcast::Sender<JobNote>,
}

impl Feed {
    pub(super) fn new(db: Db) -> Feed {
        Feed {
            db,
            tx: broadcast::Sender::new(BACKLOG),
        }
    }

    /// The notes from now on, of every job and every process.
    pub(super) fn subscribe(&self) -> broadcast::Receiver<JobNote> {
        self.tx.subscribe()
    }

    /// Tell every process sharing the database (this one included).
    /// A note that cannot be sent is only logged: followers read the table
    /// too.
    pub(super) async fn publish(&self, note: JobNote) {
        match &self.db {
            Db::Sqlite(_) => {
                // No subscriber is no error.
                let _ = self.tx.send(note);
            }
            Db::Postgres(pool) => {
                let payload = match serde_json::to_string(&note) {
                    Ok(p) => p,
                    Err(e) => {
                        tracing::warn!(costmap = %note.id, error = %e, "cannot encode a job note");
                        return;
                    }
                };
                if let Err(e) = sqlx::query("SELECT pg_notify($1, $2)")
                    .bind(CHANNEL)
                    .bind(payload)
                    .execute(pool)
                    .await
                {
                    tracing::warn!(costmap = %note.id, error = %e, "cannot send a job note");
                }
            }
        }
    }

    /// On PostgreSQL: receive the notes of every process and pass them to
    /// this one's subscribers until `stop` resolves, listening again
    /// whenever the connection is lost. Nothing to do on SQLite.
    pub(super) fn start_listening(&self, stop: impl Future<Output = ()> + Send + 'static) {
        let Db::Postgres(pool) = &self.db else {
            return;
        };
        let pool = pool.clone();
        let tx = self.tx.clone();
        tokio::spawn(async move {
            let listen = async {
                loop {
                    match listen(&pool).await {
                        Ok(mut listener) => loop {
                            match listener.recv().await {
                                Ok(n) => match serde_json::from_str::<JobNote>(n.payload()) {
                                    Ok(note) => {
                                        let _ = tx.send(note);
                                    }
                                    Err(e) => tracing::warn!(
                                        error = %e,
                                        "a job note this server cannot read (a newer version's?)"
                                    ),
                                },
                                Err(e) => {
                                    tracing::warn!(error = %e, "job notes: connection lost");
                                    break;
                                }
                            }
                        },
                        Err(e) => tracing::warn!(error = %e, "cannot listen for job notes"),
                    }
                    tokio::time::sleep(RECONNECT_AFTER).await;
                }
            };
            tokio::select! {
                () = listen => {},
                () = stop => {},
            }
        });
    }
}

async fn listen(pool: &sqlx::PgPool) -> Result<PgListener, sqlx::Error> {
    let mut listener = PgListener::connect_with(pool).await?;
    listener.listen(CHANNEL).await?;
    Ok(listener)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn notes_read_back_as_sent() {
        let note = JobNote {
            id: "0193".into(),
            status: JobStatus::Running,
            progress: 0.25,
            stage: Some(Stage::Steps),
        };
        let text = serde_json::to_string(&note).unwrap();
        assert_eq!(serde_json::from_str::<JobNote>(&text).unwrap(), note);
        // Well under PostgreSQL's 8000-byte limit on a payload.
        assert!(text.len() < 200, "{text}");
    }

    #[tokio::test]
    async fn on_sqlite_notes_reach_this_process_subscribers() {
        let dir = std::env::temp_dir().join(format!("terraplan-feed-{}", uuid::Uuid::new_v4()));
        std::fs::create_dir_all(&dir).unwrap();
        let db = Db::connect(None, &dir).await.unwrap();
        let feed = Feed::new(db.clone());
        let mut rx = feed.subscribe();
        let note = JobNote {
            id: "a".into(),
            status: JobStatus::Queued,
            progress: 0.0,
            stage: None,
        };
        feed.publish(note.clone()).await;
        assert_eq!(rx.recv().await.unwrap(), note);
        db.close().await;
        let _ = std::fs::remove_dir_all(&dir);
    }
}
