//! Writing output files atomically: into a temporary file beside the
//! target, renamed into place only when complete, so that a failed or
//! interrupted run never leaves a partial file under the requested name.

use crate::error::{Error, IoContext};
use std::path::Path;

/// A temporary file in the directory of `target`, readable by others like
/// an ordinary output file.
pub fn temp_beside(target: &Path) -> Result<tempfile::NamedTempFile, Error> {
    let dir = match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let mut b = tempfile::Builder::new();
    b.prefix(".sray-").suffix(".partial");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        b.permissions(std::fs::Permissions::from_mode(0o644));
    }
    b.tempfile_in(dir).at(target)
}

/// Moves a completed temporary file onto `target`.
pub fn persist(tmp: tempfile::NamedTempFile, target: &Path) -> Result<(), Error> {
    tmp.as_file().sync_all().at(target)?;
    tmp.persist(target)
        .map_err(|e| Error::io(target, e.error))?;
    Ok(())
}
