//! Connecting to a coordinator: URL, TLS (rustls) and the token, with the
//! message limits every side uses.

use crate::auth::{Attach, Token};
use crate::v1::coordinator_client::CoordinatorClient;
use crate::wire::MAX_MESSAGE_BYTES;
use std::path::PathBuf;
use std::time::Duration;
use tonic::service::interceptor::InterceptedService;
use tonic::transport::{Certificate, Channel, ClientTlsConfig, Endpoint, Identity};

/// A coordinator client that attaches the token to every call.
pub type Client = CoordinatorClient<InterceptedService<Channel, Attach>>;

/// How to reach a coordinator.
#[derive(Clone, Debug)]
pub struct Target {
    /// `http://HOST:PORT`, or `https://HOST:PORT` with `ca`.
    pub url: String,
    pub token: Option<Token>,
    /// PEM certificate(s) to trust for an `https` URL.
    pub ca: Option<PathBuf>,
    /// A client certificate and its key (PEM), for a coordinator that
    /// requires them (`--tls-client-ca`).
    pub identity: Option<(PathBuf, PathBuf)>,
}

impl Target {
    fn endpoint(&self) -> Result<Endpoint, String> {
        let mut ep = Endpoint::from_shared(self.url.clone())
            .map_err(|e| format!("'{}' is not a coordinator URL: {e}", self.url))?
            .connect_timeout(Duration::from_secs(5))
            .tcp_nodelay(true)
            .http2_keep_alive_interval(Duration::from_secs(10))
            .keep_alive_timeout(Duration::from_secs(20))
            .keep_alive_while_idle(true)
            .initial_stream_window_size(Some(8 << 20))
            .initial_connection_window_size(Some(16 << 20));
        if self.url.starts_with("https://") {
            let Some(ca) = &self.ca else {
                return Err(format!(
                    "{}: an https coordinator needs --tls-ca (the certificate to trust)",
                    self.url
                ));
            };
            let pem = std::fs::read(ca)
                .map_err(|e| format!("cannot read the CA certificate {}: {e}", ca.display()))?;
            let mut tls = ClientTlsConfig::new().ca_certificate(Certificate::from_pem(pem));
            if let Some((cert, key)) = &self.identity {
                let c = std::fs::read(cert)
                    .map_err(|e| format!("cannot read the certificate {}: {e}", cert.display()))?;
                let k = std::fs::read(key)
                    .map_err(|e| format!("cannot read the private key {}: {e}", key.display()))?;
                tls = tls.identity(Identity::from_pem(c, k));
            }
            ep = ep
                .tls_config(tls)
                .map_err(|e| format!("TLS settings for {}: {e}", self.url))?;
        } else if !self.url.starts_with("http://") {
            return Err(format!(
                "'{}': the coordinator URL must start with http:// or https://",
                self.url
            ));
        }
        Ok(ep)
    }

    fn client(&self, ch: Channel) -> Client {
        CoordinatorClient::with_interceptor(ch, Attach(self.token.clone()))
            .max_decoding_message_size(MAX_MESSAGE_BYTES)
            .max_encoding_message_size(MAX_MESSAGE_BYTES)
    }

    /// Connects now; the error says plainly when nothing answers.
    pub async fn connect(&self) -> Result<Client, String> {
        let ch = self.endpoint()?.connect().await.map_err(|e| {
            format!(
                "cannot reach the coordinator at {}: {}",
                self.url,
                source_chain(&e)
            )
        })?;
        Ok(self.client(ch))
    }

    /// A client that connects on first use and reconnects after failures
    /// (for workers, which outlive coordinator restarts).
    pub fn connect_lazy(&self) -> Result<Client, String> {
        Ok(self.client(self.endpoint()?.connect_lazy()))
    }
}

/// An error and its causes on one line.
pub fn source_chain(e: &(dyn std::error::Error + 'static)) -> String {
    let mut s = e.to_string();
    let mut cur = e.source();
    while let Some(c) = cur {
        let t = c.to_string();
        if !s.contains(&t) {
            s.push_str(": ");
            s.push_str(&t);
        }
        cur = c.source();
    }
    s
}
