//! `terraplan serve`: the HTTP service on its own async runtime.

use super::common::Failure;
use crate::config::ServeConfig;

pub(super) fn serve(config: ServeConfig) -> Result<(), Failure> {
    crate::memory::tune_allocator();
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| Failure::other(format!("cannot start the async runtime: {e}")))?;
    let result = runtime.block_on(crate::serve::serve(config));
    // A costmap run the shutdown cancelled may still be finishing a stage
    // on a blocking thread: do not wait for it.
    runtime.shutdown_timeout(std::time::Duration::from_secs(1));
    result.map_err(Failure::other)
}
