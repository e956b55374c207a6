//! The connection flags every client command takes (`sray render
//! --coordinator`, `sray fetch`, `sray status`).

use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug, Clone, Default)]
pub struct ClientConn {
    /// File holding the clients' token (or the cluster's shared token)
    #[arg(long)]
    pub token_file: Option<PathBuf>,
    /// Certificate (PEM) to trust for an https coordinator
    #[arg(long)]
    pub tls_ca: Option<PathBuf>,
    /// Client certificate (PEM) for a coordinator that requires one (--tls-client-ca); needs --tls-key
    #[arg(long, requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    /// The client certificate's private key (PEM)
    #[arg(long, requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
}

impl ClientConn {
    /// The coordinator at `url`, reached with these flags.
    pub fn target(&self, url: &str) -> anyhow::Result<sray_proto::net::Target> {
        Ok(sray_proto::net::Target {
            url: url.to_string(),
            token: self
                .token_file
                .as_deref()
                .map(sray_proto::auth::Token::from_file)
                .transpose()
                .map_err(anyhow::Error::msg)?,
            ca: self.tls_ca.clone(),
            identity: self.identity(),
        })
    }

    pub fn identity(&self) -> Option<(PathBuf, PathBuf)> {
        self.tls_cert.clone().zip(self.tls_key.clone())
    }
}
