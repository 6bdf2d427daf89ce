//! The byte link to a vehicle: the [`Link`] the protocol engine talks
//! through, and [`MavlinkLink`], its implementation over the `mavlink`
//! crate's UDP, TCP and serial transports.

use std::future::Future;
use std::sync::Arc;
use std::time::Duration;

use mavlink::dialects::common::MavMessage;
use mavlink::error::MessageReadError;
use mavlink::{AsyncMavConnection, MavHeader, MavlinkVersion};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;

use super::address::VehicleAddress;

/// Our MAVLink identity: a ground station (MAV_COMP_ID_MISSIONPLANNER on
/// system 255, as QGroundControl and Mission Planner use).
pub const GCS_SYSTEM: u8 = 255;
pub const GCS_COMPONENT: u8 = 190;

/// A message from the link with its sender's system id.
#[derive(Clone, Debug)]
pub struct Received {
    pub system: u8,
    pub message: MavMessage,
}

/// A link failure (not a protocol fault: those are the engine's).
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    #[error("cannot open {address}: {why}")]
    Open { address: String, why: String },
    #[error("link failed: {0}")]
    Io(String),
}

/// What the protocol engine needs of a link. `recv` must be cancel-safe:
/// the engine waits on it with a time-out and drops the future.
pub trait Link: Send {
    fn send(&mut self, message: &MavMessage) -> impl Future<Output = Result<(), LinkError>> + Send;
    fn recv(&mut self) -> impl Future<Output = Result<Received, LinkError>> + Send;
}

type Connection = mavlink::AsyncConnection<MavMessage>;

/// A `mavlink` crate connection. A task reads frames into a channel so
/// that waiting with a time-out never cuts a frame in half; it ends when
/// the link is dropped.
pub struct MavlinkLink {
    connection: Arc<Connection>,
    incoming: mpsc::Receiver<Result<Received, LinkError>>,
    reader: JoinHandle<()>,
}

impl MavlinkLink {
    /// Open the link (a TCP connect waits at most `open_timeout`).
    pub async fn open(address: &VehicleAddress, open_timeout: Duration) -> Result<Self, LinkError> {
        let text = address.connect_string();
        let fail = |why: String| LinkError::Open {
            address: text.clone(),
            why,
        };
        let mut connection: Connection =
            tokio::time::timeout(open_timeout, mavlink::connect_async::<MavMessage>(&text))
                .await
                .map_err(|_| fail(format!("no connection within {open_timeout:?}")))?
                .map_err(|e| fail(e.to_string()))?;
        connection.set_protocol_version(MavlinkVersion::V2);
        // Answer MAVLink 1 vehicles' messages too (we send version 2,
        // which every autopilot with MISSION_ITEM_INT reads).
        connection.set_allow_recv_any_version(true);
        let connection = Arc::new(connection);
        let (tx, incoming) = mpsc::channel(64);
        let reader = tokio::spawn(read_frames(connection.clone(), tx));
        Ok(MavlinkLink {
            connection,
            incoming,
            reader,
        })
    }
}

async fn read_frames(connection: Arc<Connection>, tx: mpsc::Sender<Result<Received, LinkError>>) {
    loop {
        let got = match connection.recv().await {
            Ok((header, message)) => Ok(Received {
                // MAVLink system ids are 1-255 on the wire.
                system: u8::try_from(header.system_id).unwrap_or(u8::MAX),
                message,
            }),
            // A damaged or unknown frame is skipped, as the transports
            // that retry do themselves.
            Err(MessageReadError::Parse(_)) => continue,
            Err(e) => Err(LinkError::Io(e.to_string())),
        };
        let end = got.is_err();
        if tx.send(got).await.is_err() || end {
            return;
        }
    }
}

impl Drop for MavlinkLink {
    fn drop(&mut self) {
        self.reader.abort();
    }
}

impl Link for MavlinkLink {
    async fn send(&mut self, message: &MavMessage) -> Result<(), LinkError> {
        let header = MavHeader {
            system_id: u32::from(GCS_SYSTEM),
            component_id: GCS_COMPONENT,
            sequence: 0,
        };
        self.connection
            .send(&header, message)
            .await
            .map(|_| ())
            .map_err(|e| LinkError::Io(e.to_string()))
    }

    async fn recv(&mut self) -> Result<Received, LinkError> {
        match self.incoming.recv().await {
            Some(got) => got,
            None => Err(LinkError::Io("the link's reader stopped".into())),
        }
    }
}
