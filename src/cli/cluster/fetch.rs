//! `sray fetch JOB -o OUT`: the image of a job submitted earlier, from its
//! coordinator, while the coordinator keeps it (`--job-retention`). A job
//! still running is followed to its end. Only the submitter can: the job's
//! secret is in the ticket the submitting client wrote (or give
//! `ID:SECRET`).

use super::client::{follow, load_ticket};
use crate::cli::outputs::Outputs;
use anyhow::Context;
use clap::Args;
use sray_engine::progress::NoProgress;
use sray_proto::v1;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct FetchArgs {
    /// The job: its id (the ticket written at submission holds its secret), or ID:SECRET
    pub job: String,
    /// Where to write the image (the format the job was submitted with: .png or .exr)
    #[arg(short, long)]
    pub output: PathBuf,
    /// Write the job's statistics (JSON) here
    #[arg(long)]
    pub stats: Option<PathBuf>,
    /// The coordinator (default: the one the job was submitted to, from its ticket)
    #[arg(long)]
    pub coordinator: Option<String>,
    #[command(flatten)]
    pub conn: super::conn::ClientConn,
}

pub fn run(a: FetchArgs) -> anyhow::Result<()> {
    let t = load_ticket(&a.job)?;
    let url = a
        .coordinator
        .clone()
        .or_else(|| Some(t.coordinator.clone()).filter(|u| !u.is_empty()))
        .context("which coordinator? (--coordinator URL)")?;
    let target = sray_proto::net::Target {
        url,
        token: a
            .conn
            .token_file
            .as_deref()
            .or(t.token_file.as_deref())
            .map(sray_proto::auth::Token::from_file)
            .transpose()
            .map_err(anyhow::Error::msg)?,
        ca: a.conn.tls_ca.clone().or(t.tls_ca.clone()),
        identity: a.conn.identity().or(t.tls_identity.clone()),
    };
    let outputs = Outputs::open(&a.output, a.stats.as_deref())?;
    let format = outputs.format();
    let job = v1::JobRef {
        job_id: t.job_id,
        job_secret: t.job_secret,
    };
    let rt = super::super::cluster_cmd::runtime()?;
    let r = rt.block_on(async {
        let client = target.connect().await.map_err(anyhow::Error::msg)?;
        follow(&target, Some(client), &job, format, &NoProgress).await
    })?;
    outputs.write(&r.image, &r.stats)?;
    Ok(())
}
