//! Serving the coordinator: the gRPC service on a listener, with the token
//! check, TLS when given a certificate, and the heartbeat monitor.

use crate::service::Service;
use crate::state::{Shared, monitor};
use anyhow::Context;
use sray_proto::auth::{Check, Token};
use sray_proto::v1::coordinator_server::CoordinatorServer;
use sray_proto::wire::MAX_MESSAGE_BYTES;
use std::path::PathBuf;
use std::sync::Arc;
use tokio::net::TcpListener;
use tonic::service::interceptor::InterceptedService;
use tonic::transport::{Identity, Server, ServerTlsConfig};

/// Security settings of a coordinator.
#[derive(Clone, Debug, Default)]
pub struct Security {
    pub token: Option<Token>,
    /// PEM certificate chain and private key: serve TLS.
    pub tls: Option<(PathBuf, PathBuf)>,
}

/// HTTP/2 flow-control window, bytes.
pub const WINDOW: u32 = 8 << 20;

/// Accepted connections with Nagle's algorithm off: small messages
/// (heartbeats, task requests, window updates) must not wait 40 ms for a
/// delayed acknowledgement.
fn incoming(
    listener: TcpListener,
) -> impl tokio_stream::Stream<Item = std::io::Result<tokio::net::TcpStream>> {
    tokio_stream::StreamExt::map(
        tokio_stream::wrappers::TcpListenerStream::new(listener),
        |s| {
            let s = s?;
            s.set_nodelay(true)?;
            Ok(s)
        },
    )
}

/// Serves until `shutdown` completes.
pub async fn serve(
    shared: Arc<Shared>,
    listener: TcpListener,
    sec: Security,
    shutdown: impl std::future::Future<Output = ()>,
) -> anyhow::Result<()> {
    // Record streams are megabytes: windows large enough that a stream is
    // not paced by window updates.
    let mut builder = Server::builder()
        .http2_keepalive_interval(Some(std::time::Duration::from_secs(10)))
        .http2_keepalive_timeout(Some(std::time::Duration::from_secs(20)))
        .initial_stream_window_size(Some(WINDOW))
        .initial_connection_window_size(Some(2 * WINDOW));
    if let Some((cert, key)) = &sec.tls {
        let c = std::fs::read(cert)
            .with_context(|| format!("cannot read the certificate {}", cert.display()))?;
        let k = std::fs::read(key)
            .with_context(|| format!("cannot read the private key {}", key.display()))?;
        builder = builder
            .tls_config(ServerTlsConfig::new().identity(Identity::from_pem(c, k)))
            .context("TLS settings")?;
    }
    let svc = CoordinatorServer::new(Service {
        shared: shared.clone(),
    })
    .max_decoding_message_size(MAX_MESSAGE_BYTES)
    .max_encoding_message_size(MAX_MESSAGE_BYTES);
    let svc = InterceptedService::new(svc, Check(sec.token));
    let mon = tokio::spawn(monitor(shared));
    let r = builder
        .add_service(svc)
        .serve_with_incoming_shutdown(incoming(listener), shutdown)
        .await;
    mon.abort();
    r.context("the coordinator's server failed")
}
