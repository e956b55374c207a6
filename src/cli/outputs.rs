//! The files a render writes: the image and, when asked, the statistics.
//! Both are opened (as temporary files beside their targets) before the
//! render starts, so that an unwritable path fails at once instead of after
//! an hour of tracing; both are renamed into place only when both are
//! complete, so a failure never leaves one without the other or a partial
//! file under either name. The image's format follows its extension
//! (.png or .exr), checked here too, before any work.

use sray_engine::fsutil::{persist, temp_beside};
use sray_engine::render::ImageFormat;
use std::io::Write;
use std::path::{Path, PathBuf};
use tempfile::NamedTempFile;

pub struct Outputs {
    format: ImageFormat,
    image: (PathBuf, NamedTempFile),
    stats: Option<(PathBuf, NamedTempFile)>,
}

impl Outputs {
    pub fn open(image: &Path, stats: Option<&Path>) -> anyhow::Result<Outputs> {
        if stats == Some(image) {
            anyhow::bail!("--stats and -o name the same file, {}", image.display());
        }
        let format = ImageFormat::from_path(image)?;
        Ok(Outputs {
            format,
            image: (image.to_path_buf(), temp_beside(image)?),
            stats: stats
                .map(|p| Ok::<_, anyhow::Error>((p.to_path_buf(), temp_beside(p)?)))
                .transpose()?,
        })
    }

    /// The format the image file is to be in, by its extension.
    pub fn format(&self) -> ImageFormat {
        self.format
    }

    /// Writes the image file's bytes and the statistics, then moves both
    /// into place. Unwritten temporary files are removed when dropped.
    pub fn write(self, image_file: &[u8], stats: &impl serde::Serialize) -> anyhow::Result<()> {
        self.write_with(
            |out| {
                out.write_all(image_file)?;
                Ok(())
            },
            stats,
        )
    }

    /// As [`Outputs::write`], the image written by `image` into the
    /// (buffered) temporary file: an image need not be in memory whole.
    pub fn write_with(
        self,
        image: impl FnOnce(&mut dyn Write) -> anyhow::Result<()>,
        stats: &impl serde::Serialize,
    ) -> anyhow::Result<()> {
        let (image_path, tmp) = self.image;
        let mut buffered = std::io::BufWriter::with_capacity(1 << 20, tmp);
        image(&mut buffered).map_err(|e| e.context(format!("writing {}", image_path.display())))?;
        let image = buffered
            .into_inner()
            .map_err(|e| sray_engine::Error::io(&image_path, e.into_error()))?;
        let stats = match self.stats {
            Some((p, mut tmp)) => {
                let mut text = serde_json::to_vec_pretty(stats)?;
                text.push(b'\n');
                tmp.write_all(&text)
                    .map_err(|e| sray_engine::Error::io(&p, e))?;
                tmp.as_file()
                    .sync_all()
                    .map_err(|e| sray_engine::Error::io(&p, e))?;
                Some((p, tmp))
            }
            None => None,
        };
        persist(image, &image_path)?;
        if let Some((p, tmp)) = stats
            && let Err(e) = persist(tmp, &p)
        {
            let _ = std::fs::remove_file(&image_path);
            return Err(e.into());
        }
        Ok(())
    }
}
