//! Serving the coordinator: the gRPC service on a listener, with the token
//! and role check, TLS when given a certificate (and client certificates
//! when given a CA for them), the heartbeat monitor, and the journal's
//! unfinished jobs resumed at start. Beside it on the same port, without
//! a token (probes and tools carry none, and neither reveals anything
//! beyond the public `sray.proto`): standard gRPC health
//! (`grpc.health.v1.Health`: `""` and `sray.v1.Coordinator` are SERVING
//! until the coordinator stops) and server reflection (v1 and v1alpha).
//! Optionally an HTTP listener for operators ([`crate::http`]).
//!
//! Stopping (SIGTERM, Ctrl-C): new work is refused, watchers and long
//! polls end at once with "coordinator restarting", running jobs stop
//! where they are (each resumes from its last finished round at the next
//! start), and the server is given [`STOP_GRACE`] to close its
//! connections before the process exits regardless.

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
use tonic::transport::{Certificate, Identity, Server, ServerTlsConfig};

/// Security settings of a coordinator.
#[derive(Clone, Debug, Default)]
pub struct Security {
    /// The token workers present.
    pub worker_token: Option<Token>,
    /// The token clients present.
    pub client_token: Option<Token>,
    /// PEM certificate chain and private key: serve TLS.
    pub tls: Option<(PathBuf, PathBuf)>,
    /// PEM CA certificate(s): with TLS, every caller must present a
    /// certificate signed by one of them.
    pub client_ca: Option<PathBuf>,
}

/// How long the server may take to close its connections once stopping.
pub const STOP_GRACE: std::time::Duration = std::time::Duration::from_secs(2);

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
    serve_with(shared, listener, None, sec, shutdown).await
}

/// As [`serve`], with the operators' HTTP listener (`--http-listen`) when
/// given one.
pub async fn serve_with(
    shared: Arc<Shared>,
    listener: TcpListener,
    http: Option<TcpListener>,
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
        let mut tls = ServerTlsConfig::new().identity(Identity::from_pem(c, k));
        if let Some(ca) = &sec.client_ca {
            let pem = std::fs::read(ca)
                .with_context(|| format!("cannot read the client CA {}", ca.display()))?;
            tls = tls.client_ca_root(Certificate::from_pem(pem));
        }
        builder = builder.tls_config(tls).context("TLS settings")?;
    } else if sec.client_ca.is_some() {
        anyhow::bail!(
            "--tls-client-ca needs --tls-cert and --tls-key (client certificates need TLS)"
        );
    }
    let svc = CoordinatorServer::new(Service {
        shared: shared.clone(),
    })
    .max_decoding_message_size(MAX_MESSAGE_BYTES)
    .max_encoding_message_size(MAX_MESSAGE_BYTES);
    let svc = InterceptedService::new(
        svc,
        Check {
            worker: sec.worker_token,
            client: sec.client_token,
        },
    );
    let (health, health_svc) = tonic_health::server::health_reporter();
    health.set_serving::<CoordinatorServer<Service>>().await;
    let reflection = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(sray_proto::FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
        .build_v1()
        .context("gRPC reflection")?;
    let reflection_alpha = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(sray_proto::FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
        .build_v1alpha()
        .context("gRPC reflection")?;
    let (http_stop_tx, http_stop_rx) = tokio::sync::oneshot::channel::<()>();
    let http_task = http.map(|l| {
        tokio::spawn(crate::http::serve(shared.clone(), l, async {
            let _ = http_stop_rx.await;
        }))
    });
    let mon = tokio::spawn(monitor::run(shared.clone()));
    crate::driver::resume_all(&shared).await;
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let server = builder
        .add_service(svc)
        .add_service(health_svc)
        .add_service(reflection)
        .add_service(reflection_alpha)
        .serve_with_incoming_shutdown(incoming(listener), async {
            let _ = stop_rx.await;
        });
    tokio::pin!(server);
    let r = tokio::select! {
        r = &mut server => r,
        _ = shutdown => {
            let t0 = std::time::Instant::now();
            tracing::info!("stopping: refusing new work; running jobs resume at the next start");
            shared.begin_stop();
            health.set_not_serving::<CoordinatorServer<Service>>().await;
            health
                .set_service_status("", tonic_health::ServingStatus::NotServing)
                .await;
            for e in shared.jobs.running() {
                if let Some(h) = e.driver.lock().unwrap_or_else(|p| p.into_inner()).take() {
                    h.abort();
                }
            }
            let _ = stop_tx.send(());
            let r = match tokio::time::timeout(STOP_GRACE, &mut server).await {
                Ok(r) => r,
                Err(_) => Ok(()),
            };
            tracing::info!(seconds = t0.elapsed().as_secs_f64(), "coordinator stopped");
            r
        }
    };
    mon.abort();
    let _ = http_stop_tx.send(());
    if let Some(h) = http_task {
        // Dashboards poll with keep-alive: do not wait for them long.
        let _ = tokio::time::timeout(std::time::Duration::from_millis(500), h).await;
    }
    r.context("the coordinator's server failed")
}
