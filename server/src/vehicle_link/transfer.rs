//! A whole send: each list uploaded, then read back and compared with
//! what was sent, in the order given (mission, fence, rally).

use super::compare::first_difference;
use super::connection::Link;
use super::download::download;
use super::exchange::{Options, Progress, ProtocolError, cancel_transfer};
use super::items::MissionKind;
use super::mission_file::ItemList;
use super::upload::upload;

/// What arrived: per list, its kind and item count (all read back equal).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Sent {
    pub kind: super::items::MissionKind,
    pub items: usize,
}

/// Tell the vehicle a transfer of `kind` it may be in is over (MISSION_ACK
/// OPERATION_CANCELLED): for a send abandoned midway, e.g. when the
/// service's client went away, so the vehicle need not wait for its own
/// time-out.
pub async fn cancel<L: Link>(link: &mut L, opts: &Options, kind: MissionKind) {
    cancel_transfer(link, opts, kind).await;
}

/// Upload each list and verify its read-back; stops at the first fault.
pub async fn send_and_verify<L: Link>(
    link: &mut L,
    opts: &Options,
    lists: &[ItemList],
    progress: &mut (dyn FnMut(Progress) + Send),
) -> Result<Vec<Sent>, ProtocolError> {
    let mut sent = Vec::with_capacity(lists.len());
    for list in lists {
        upload(link, opts, list.kind, &list.items, progress).await?;
        let got = download(link, opts, list.kind, progress).await?;
        if let Some(why) = first_difference(&list.items, &got, list.home_first) {
            return Err(ProtocolError::Mismatch {
                kind: list.kind,
                why,
            });
        }
        sent.push(Sent {
            kind: list.kind,
            items: list.items.len(),
        });
    }
    Ok(sent)
}
