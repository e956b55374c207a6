//! `sray status --coordinator URL [--json]`: the cluster's workers and
//! jobs, as tables (or one JSON object with `workers` and `jobs`).

use super::conn::ClientConn;
use clap::Args;
use sray_proto::v1;
use std::fmt::Write;

#[derive(Args, Debug)]
pub struct StatusArgs {
    /// The coordinator's URL (http://HOST:PORT, or https:// with --tls-ca)
    #[arg(long)]
    pub coordinator: String,
    /// Print one JSON object with keys `workers` and `jobs` (arrays)
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub conn: ClientConn,
}

pub fn run(a: StatusArgs) -> anyhow::Result<()> {
    let target = a.conn.target(&a.coordinator)?;
    let rt = super::super::cluster_cmd::runtime()?;
    let reply = rt.block_on(async {
        let mut client = target.connect().await.map_err(anyhow::Error::msg)?;
        let r = tokio::time::timeout(
            std::time::Duration::from_secs(30),
            client.status(v1::StatusRequest {}),
        )
        .await
        .map_err(|_| anyhow::anyhow!("the coordinator did not answer within 30 s"))?;
        match r {
            Ok(r) => Ok(r.into_inner()),
            Err(s) if s.code() == tonic::Code::Unimplemented => anyhow::bail!(
                "the coordinator at {} does not answer Status: it runs an older sray",
                a.coordinator
            ),
            Err(s) => anyhow::bail!("status: {}", s.message()),
        }
    })?;
    if a.json {
        crate::cli::print_stdout(&format!(
            "{}\n",
            serde_json::to_string_pretty(&sray_coordinator::status::to_json(&reply))?
        ))?;
    } else {
        crate::cli::print_stdout(&table(&reply))?;
    }
    Ok(())
}

fn time(unix: u64) -> String {
    if unix == 0 {
        return "-".into();
    }
    let s = unix % 86_400;
    format!("{:02}:{:02}:{:02}Z", s / 3600, s / 60 % 60, s % 60)
}

fn secs(s: f64) -> String {
    if s < 0.0 {
        "?".into()
    } else if s < 90.0 {
        format!("{s:.0}s")
    } else if s < 5400.0 {
        format!("{:.1}m", s / 60.0)
    } else {
        format!("{:.1}h", s / 3600.0)
    }
}

/// Columns padded to their widest cell.
fn grid(head: &[&str], rows: &[Vec<String>]) -> String {
    let mut w: Vec<usize> = head.iter().map(|h| h.len()).collect();
    for r in rows {
        for (i, c) in r.iter().enumerate() {
            w[i] = w[i].max(c.chars().count());
        }
    }
    let mut out = String::new();
    let line = |cells: Vec<String>, out: &mut String| {
        let s: Vec<String> = cells
            .iter()
            .enumerate()
            .map(|(i, c)| format!("{c:<0$}", w[i]))
            .collect();
        let _ = writeln!(out, "{}", s.join("  ").trim_end());
    };
    line(head.iter().map(|h| h.to_string()).collect(), &mut out);
    for r in rows {
        line(r.clone(), &mut out);
    }
    out
}

fn table(r: &v1::StatusReply) -> String {
    let mut out = format!(
        "coordinator run {}, up {}, {} tasks queued\n\nWORKERS ({})\n",
        r.run_id.get(..8).unwrap_or(&r.run_id),
        secs(r.uptime_seconds),
        r.queued_tasks,
        r.workers.len()
    );
    let rows: Vec<Vec<String>> = r
        .workers
        .iter()
        .map(|w| {
            vec![
                w.id.clone(),
                w.name.clone(),
                w.address.clone(),
                w.state.clone(),
                if w.tasks.is_empty() {
                    "-".into()
                } else {
                    w.tasks.join("; ")
                },
                format!("{}MiB", w.memory_bytes >> 20),
                w.threads.to_string(),
                w.tasks_done.to_string(),
                w.failures.to_string(),
                if w.quarantined { "yes" } else { "no" }.into(),
            ]
        })
        .collect();
    out += &grid(
        &[
            "ID",
            "NAME",
            "ADDRESS",
            "STATE",
            "TASK",
            "MEMORY",
            "THREADS",
            "DONE",
            "FAILURES",
            "QUARANTINED",
        ],
        &rows,
    );
    let _ = write!(out, "\nJOBS ({})\n", r.jobs.len());
    let rows: Vec<Vec<String>> = r
        .jobs
        .iter()
        .map(|j| {
            vec![
                j.id.clone(),
                j.scene.get(..12).unwrap_or(&j.scene).to_string(),
                format!("{}x{}", j.width, j.height),
                if j.error.is_empty() {
                    j.state.clone()
                } else {
                    format!(
                        "{}: {}",
                        j.state,
                        j.error.chars().take(60).collect::<String>()
                    )
                },
                format!(
                    "{} {}",
                    j.round,
                    sray_coordinator::status::stage_name(j.stage)
                )
                .trim()
                .to_string(),
                format!("{:.1}%", j.progress_percent),
                if j.state == "running" {
                    secs(j.eta_seconds)
                } else {
                    "-".into()
                },
                time(j.submitted_unix),
                time(j.started_unix),
                time(j.finished_unix),
            ]
        })
        .collect();
    out += &grid(
        &[
            "ID",
            "SCENE",
            "SIZE",
            "STATE",
            "ROUND",
            "PROGRESS",
            "ETA",
            "SUBMITTED",
            "STARTED",
            "FINISHED",
        ],
        &rows,
    );
    out
}
