//! A job request checked against the coordinator's limits, and what the
//! rounds need to know of it (its scene, settings, bounds).

use crate::scenes::Scene;
use crate::state::Shared;
use anyhow::{Context, bail};
use sray_engine::bf::StoreNumber;
use sray_engine::render::{Camera, ImageFormat, RenderOptions, epsilon};
use sray_engine::sdb::Database;
use sray_proto::v1;
use std::sync::Arc;

/// A checked job, ready to run.
pub struct Job {
    pub scene: Arc<Scene>,
    pub hash: String,
    pub params: v1::RenderParams,
    pub opts: RenderOptions,
    pub store: StoreNumber,
    pub shard_rays: u64,
    /// The job left the shard size to the coordinator (see [`super::shards::shard_size`]).
    pub auto_shard: bool,
    /// The format of the image sent back.
    pub format: ImageFormat,
    pub objects: u64,
    /// The most triangles of any model the scene's instances place.
    pub model_triangles: u64,
    pub eps: f64,
    pub grids: Vec<sray_engine::grid::GridStat>,
}

/// Fewest and most rays per shard a job may ask for.
const SHARD_RAYS: std::ops::RangeInclusive<u64> = 256..=(1 << 24);

/// The memory the grid statistics of a job are planned for: each worker
/// plans its own grid from its own `--memory` (results do not depend on
/// the grid), so the statistics name a nominal one.
const NOMINAL_MEMORY: u64 = 1 << 30;

impl Job {
    /// Checks a job request against the coordinator's limits (before
    /// anything is allocated for it): the scene is here, the settings are
    /// sane and within bounds.
    pub async fn check(shared: &Arc<Shared>, spec: &v1::JobSpec) -> anyhow::Result<Job> {
        let l = &shared.cfg.limits;
        let params = spec.params.context("a job needs render settings")?;
        let pixels = params.width as u64 * params.height as u64;
        if pixels > l.max_pixels {
            bail!(
                "{}x{} is {pixels} pixels: this coordinator renders at most {} (--max-pixels)",
                params.width,
                params.height,
                l.max_pixels
            );
        }
        if params.samples > l.max_samples {
            bail!(
                "{} samples per pixel: this coordinator takes at most {} (--max-samples)",
                params.samples,
                l.max_samples
            );
        }
        if params.max_depth > l.max_depth {
            bail!(
                "depth {}: this coordinator takes at most {} (--max-depth)",
                params.max_depth,
                l.max_depth
            );
        }
        let voxels = params.grid_res_x as u64 * params.grid_res_y as u64 * params.grid_res_z as u64;
        if voxels > l.max_grid_voxels {
            bail!(
                "a {}x{}x{} grid: at most {} voxels here",
                params.grid_res_x,
                params.grid_res_y,
                params.grid_res_z,
                l.max_grid_voxels
            );
        }
        let hash = spec
            .scene
            .as_ref()
            .map(|s| s.hash.clone())
            .unwrap_or_default();
        let sh = shared.clone();
        let h = hash.clone();
        let scene = tokio::task::spawn_blocking(move || sh.scenes.get(&h))
            .await??
            .with_context(|| format!("no scene {hash} here: upload it first"))?;
        if scene.size > l.max_scene_bytes {
            bail!(
                "the scene has {} bytes: at most {} here (--max-scene-bytes)",
                scene.size,
                l.max_scene_bytes
            );
        }
        let (opts, store) =
            sray_worker::params::from_proto(&params, 0).map_err(anyhow::Error::msg)?;
        // 0 (the job's and the coordinator's): sized for the cluster.
        let shard_rays = match spec.shard_rays {
            0 => shared.cfg.shard_rays,
            n if SHARD_RAYS.contains(&n) => n,
            n => bail!("{n} rays per shard is out of range {SHARD_RAYS:?}"),
        };
        let format = match v1::ImageFormat::try_from(spec.image_format) {
            Ok(v1::ImageFormat::Png) => ImageFormat::Png,
            Ok(v1::ImageFormat::Exr) => ImageFormat::Exr,
            Err(_) => bail!(
                "image format {} is unknown here: this coordinator writes PNG or OpenEXR",
                spec.image_format
            ),
        };
        let path = scene.path.clone();
        let o = opts.clone();
        let ((objects, model_triangles), eps, grids) =
            tokio::task::spawn_blocking(move || -> anyhow::Result<_> {
                let db = Database::open(&path)?;
                Camera::new(&db.scene().view, o.width, o.height)?;
                let (specs, _) = sray_engine::bf::plan_grids(&db, &o, NOMINAL_MEMORY);
                let groups =
                    sray_engine::grid::plan_groups(db.sizes(), db.density(), o.multiple_grids);
                let grids: Vec<_> = specs
                    .iter()
                    .zip(&groups.counts)
                    .map(|(s, &n)| sray_engine::grid::GridStat {
                        objects: n,
                        resolution: s.res,
                        lo: s.lo,
                        hi: s.hi,
                        nested_voxels: 0,
                        nested_objects: 0,
                        aggregates: 0,
                    })
                    .collect();
                // The most triangles any model has: no instance hit can name
                // a triangle past it.
                let mut model_triangles = 0;
                for m in 0..db.models().len() {
                    model_triangles = model_triangles.max(db.open_model(m)?.object_count());
                }
                Ok((
                    (db.object_count(), model_triangles),
                    epsilon(&db.bbox(), o.precision),
                    grids,
                ))
            })
            .await??;
        Ok(Job {
            objects,
            model_triangles,
            eps,
            scene,
            hash,
            params,
            opts,
            store,
            shard_rays,
            auto_shard: shard_rays == 0,
            format,
            grids,
        })
    }
}
