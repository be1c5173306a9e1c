//! The one loop that serves every service of the node (Rollout, Replay,
//! Train, LoadModel): take a request, do the work on tokio's blocking pool,
//! send the reply. Each request runs as its own task, so a long call (a
//! training) never holds up the next request; an undecodable request, a
//! failed task and a failed send are logged, never fatal.
//!
//! The work gets a context of the caller's choosing (the node's handles, the
//! trainer), so this module depends on no task module.

use std::future::Future;
use std::sync::Arc;

use ros2_client::log::LogLevel;
use ros2_client::{Message, Server};

use super::handles::{Diagnostics, Warning};
use super::wire::{
    LoadModelResponse, PlanResponse, ReplayResponse, RolloutResponse, TrainResponse,
};

/// A service reply that can say it failed.
pub trait Reply: Message + Send + Sync + 'static {
    /// A failed reply giving `message` as the reason.
    fn failure(message: String) -> Self;
    /// The reason, when the reply reports a failure.
    fn failure_reason(&self) -> Option<&str>;
}

macro_rules! reply {
    ($($t:ty),*) => {$(
        impl Reply for $t {
            // LoadModelResponse has no other fields; the others do.
            #[allow(clippy::needless_update)]
            fn failure(message: String) -> Self {
                Self { success: false, message, ..Self::default() }
            }
            fn failure_reason(&self) -> Option<&str> {
                (!self.success).then_some(self.message.as_str())
            }
        }
    )*};
}
reply!(
    RolloutResponse,
    ReplayResponse,
    TrainResponse,
    LoadModelResponse,
    PlanResponse
);

/// How a service's failures are reported besides the reply itself.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OnFailure {
    /// A rate-limited warning and the node's `last_error`.
    Warn,
    /// Nothing more: the work logs its own failures.
    Quiet,
}

/// Serves `server` (named `name` in messages) until the task is cancelled:
/// every request is answered with `work(ctx, request)`, run on the blocking
/// pool in a task of its own; failures go to `diag`.
pub fn serve<C, Req, Resp, W>(
    ctx: C,
    diag: Arc<Diagnostics>,
    server: Server<Req, Resp>,
    name: &'static str,
    on_failure: OnFailure,
    work: W,
) -> impl Future<Output = ()> + Send + 'static
where
    C: Clone + Send + Sync + 'static,
    Req: Message + Send + Sync + 'static,
    Resp: Reply,
    W: Fn(&C, Req) -> Resp + Send + Sync + 'static,
{
    let server = Arc::new(server);
    let work = Arc::new(work);
    async move {
        loop {
            let (id, req) = match server.async_receive_request().await {
                Ok(r) => r,
                Err(e) => {
                    diag.log(
                        LogLevel::Warn,
                        &format!("undecodable {name} request: {e:?}"),
                    );
                    continue;
                }
            };
            let (ctx, diag, server, work) =
                (ctx.clone(), diag.clone(), server.clone(), work.clone());
            tokio::spawn(async move {
                let job = tokio::task::spawn_blocking(move || work(&ctx, req));
                let resp = job
                    .await
                    .unwrap_or_else(|join| Resp::failure(format!("{name} task failed: {join}")));
                if let (OnFailure::Warn, Some(why)) = (on_failure, resp.failure_reason()) {
                    diag.failed(&format!("{name} call failed: {why}"), Warning::Service);
                }
                if let Err(e) = server.async_send_response(id, resp).await {
                    diag.log(
                        LogLevel::Warn,
                        &format!("sending a {name} response failed: {e:?}"),
                    );
                }
            });
        }
    }
}
