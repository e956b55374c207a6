//! The benchmark report: Markdown, with data files and charts beside it.

use std::fmt::Write;
use std::path::{Path, PathBuf};

pub struct Report {
    pub dir: PathBuf,
    pub md: String,
}

impl Report {
    pub fn new(dir: &Path) -> anyhow::Result<Report> {
        std::fs::create_dir_all(dir)?;
        Ok(Report {
            dir: dir.to_path_buf(),
            md: String::new(),
        })
    }

    pub fn section(&mut self, title: &str) {
        let _ = write!(self.md, "\n## {title}\n\n");
    }

    pub fn para(&mut self, text: &str) {
        let _ = write!(self.md, "{text}\n\n");
    }

    /// A Markdown table, also written as `name.csv`.
    pub fn table(
        &mut self,
        name: &str,
        header: &[&str],
        rows: &[Vec<String>],
    ) -> anyhow::Result<()> {
        let _ = writeln!(self.md, "| {} |", header.join(" | "));
        let _ = writeln!(self.md, "|{}", "---|".repeat(header.len()));
        for r in rows {
            let _ = writeln!(self.md, "| {} |", r.join(" | "));
        }
        self.md.push('\n');
        let mut csv = header.join(",");
        csv.push('\n');
        for r in rows {
            csv.push_str(
                &r.iter()
                    .map(|c| c.replace(',', ";"))
                    .collect::<Vec<_>>()
                    .join(","),
            );
            csv.push('\n');
        }
        std::fs::write(self.dir.join(format!("{name}.csv")), csv)?;
        Ok(())
    }

    /// Links a chart written at `file` (relative to the report).
    pub fn chart(&mut self, file: &str, alt: &str) {
        let _ = write!(self.md, "![{alt}]({file})\n\n");
    }

    pub fn json(&self, name: &str, v: &serde_json::Value) -> anyhow::Result<()> {
        std::fs::write(
            self.dir.join(format!("{name}.json")),
            serde_json::to_string_pretty(v)?,
        )?;
        Ok(())
    }

    pub fn path(&self, file: &str) -> PathBuf {
        self.dir.join(file)
    }

    pub fn finish(&self, title: &str, preamble: &str) -> anyhow::Result<PathBuf> {
        let p = self.dir.join("REPORT.md");
        std::fs::write(&p, format!("# {title}\n\n{preamble}\n{}", self.md))?;
        Ok(p)
    }
}

/// `1.234` with `digits` decimals, or `-` for a missing number.
pub fn num(v: f64, digits: usize) -> String {
    if v.is_finite() {
        format!("{v:.digits$}")
    } else {
        "-".into()
    }
}
