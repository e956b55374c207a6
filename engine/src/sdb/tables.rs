//! The tables at the end of a database: the view, background, lights and
//! materials, the size and density summaries, and the models' places.

use super::database::ModelEntry;
use super::format::*;
use crate::scene::ImageData;
use crate::scene::density::MAX_ENTRIES as MAX_DENSITY_ENTRIES;
use crate::scene::{
    Aabb, DENSITY_CELLS, DensitySummary, Light, LightKind, Material, Pbr, Photometric,
    SIZE_CLASSES, SceneHeader, SizeClass, SizeSummary, TextureBinding, TextureImage, TiledImage,
    View,
};
use crate::texture::{Encoding, Filter, Sampler, TileRef, UvTransform, Wrap};

/// What the tables hold, decoded.
pub(super) type Tables = (
    SceneHeader,
    SizeSummary,
    Option<DensitySummary>,
    Vec<ModelEntry>,
    TilesSection,
);

/// Where a version 9 database's texture tiles lie: from `offset`, `bytes`
/// long, between the last block and the tables (both zero when it has
/// none).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(super) struct TilesSection {
    pub offset: u64,
    pub bytes: u64,
}

/// The tables: the scene's header, the size summary, (`density`: from
/// version 3 on) the density summary, (`appearance`: version 7) the glTF
/// materials and lights (`textures`: version 8, then the materials'
/// textures and their images; `tiled`: version 9, the images as tiles),
/// and (`with_models`) the models.
pub(super) fn decode_tables(
    buf: &[u8],
    density: bool,
    appearance: bool,
    textures: bool,
    tiled: bool,
    with_models: bool,
) -> Option<Tables> {
    let mut d = Dec { buf, pos: 0 };
    let v3 = |d: &mut Dec| -> Option<[f64; 3]> { Some([d.f64()?, d.f64()?, d.f64()?]) };
    let from = v3(&mut d)?;
    let at = v3(&mut d)?;
    let up = v3(&mut d)?;
    let view = View {
        from,
        at,
        up,
        angle: d.f64()?,
        hither: d.f64()?,
        resolution: [d.u32()?, d.u32()?],
    };
    let background = [d.f32()?, d.f32()?, d.f32()?];
    let nl = d.u32()? as usize;
    if nl > MAX_LIGHTS || nl * 40 > d.remaining() {
        return None;
    }
    let mut lights = Vec::with_capacity(nl);
    for _ in 0..nl {
        let position = v3(&mut d)?;
        let has = d.u32()?;
        let c = [d.f32()?, d.f32()?, d.f32()?];
        lights.push(Light {
            photometric: None,
            position,
            color: (has != 0).then_some(c),
        });
    }
    let nm = d.u32()? as usize;
    if nm > MAX_MATERIALS || nm * 32 > d.remaining() {
        return None;
    }
    let mut materials = Vec::with_capacity(nm);
    for _ in 0..nm {
        let mut m = [0f32; 8];
        for x in &mut m {
            *x = d.f32()?;
        }
        materials.push(Material {
            pbr: None,
            texture: None,
            maps: crate::scene::Maps::NONE,
            color: [m[0], m[1], m[2]],
            kd: m[3],
            ks: m[4],
            shine: m[5],
            t: m[6],
            ior: m[7],
        });
    }
    let mut sizes = SizeSummary::default();
    let nc = d.u32()? as usize;
    if nc > SIZE_CLASSES || nc * 36 > d.remaining() || (!density && nc * 36 != d.remaining()) {
        return None;
    }
    for _ in 0..nc {
        let i = d.u32()? as usize;
        let count = d.u64()?;
        let mut b = [0f32; 6];
        for x in &mut b {
            *x = d.f32()?;
        }
        let c = sizes.classes.get_mut(i)?;
        c.count = count;
        c.bounds = Aabb::from_array(b);
    }
    // Counts that do not add up in a u64 are corrupt (the sum is checked
    // against the header's object count later).
    sizes
        .classes
        .iter()
        .try_fold(0u64, |a, c| a.checked_add(c.count))?;
    let density = if density {
        let level = d.u32()? as i32;
        let origin = [d.u64()? as i64, d.u64()? as i64, d.u64()? as i64];
        // Cell coordinates stay exact in an f64 (see the writer).
        if origin.iter().any(|o| o.unsigned_abs() > 1 << 52) {
            return None;
        }
        let n = d.u32()? as usize;
        if n > MAX_DENSITY_ENTRIES
            || n * 40 > d.remaining()
            || (!with_models && !appearance && n * 40 != d.remaining())
        {
            return None;
        }
        let mut entries = Vec::with_capacity(n);
        for _ in 0..n {
            let cell = d.u32()?;
            let class = d.u32()?;
            let count = d.u64()?;
            let mut b = [0f32; 6];
            for x in &mut b {
                *x = d.f32()?;
            }
            if cell >= (DENSITY_CELLS * DENSITY_CELLS * DENSITY_CELLS) as u32
                || class >= SIZE_CLASSES as u32
            {
                return None;
            }
            let bounds = Aabb::from_array(b);
            entries.push(((cell, class as u8), SizeClass { count, bounds }));
        }
        // No more objects than the size summary counts (the writer leaves
        // out only objects with empty boxes).
        let total = entries
            .iter()
            .try_fold(0u64, |a, e| a.checked_add(e.1.count))?;
        if total > sizes.total() {
            return None;
        }
        // Level i32::MIN: the writer kept no summary.
        (level != i32::MIN && (-1100..=1100).contains(&level))
            .then(|| DensitySummary::from_parts(level, origin, entries))
    } else {
        None
    };
    let mut images = Vec::new();
    let mut section = TilesSection::default();
    if appearance {
        decode_appearance(&mut d, &mut lights, &mut materials)?;
        if textures {
            decode_bindings(&mut d, &mut materials, tiled)?;
            if tiled {
                (images, section) = decode_tiled_images(&mut d)?;
            } else {
                images = decode_images(&mut d)?;
            }
        }
        if !with_models && d.remaining() != 0 {
            return None;
        }
    }
    let mut models = Vec::new();
    if with_models {
        let n = d.u32()? as usize;
        if n > MAX_MODELS || n * 32 != d.remaining() {
            return None;
        }
        for _ in 0..n {
            let offset = d.u64()?;
            let bytes = d.u64()?;
            let pad = d.f64()?;
            if d.u64()? != 0 {
                return None;
            }
            models.push(ModelEntry { offset, bytes, pad });
        }
    }
    Some((
        SceneHeader {
            view,
            background,
            lights,
            materials,
            textures: images,
        },
        sizes,
        density,
        models,
        section,
    ))
}

/// Bytes of one material's and one light's entry in the appearance table.
const PBR_ENTRY: usize = 4 * 6;
const LIGHT_ENTRY: usize = 4 * 6 + 8 * 3;

/// The appearance table (version 7): the glTF materials' metallic-roughness
/// parameters and the glTF lights' photometry, each entry naming the
/// material or light it belongs to, in increasing order. `None` when
/// the scene has neither (the table is then not written at all).
pub(super) fn encode_appearance(lights: &[Light], materials: &[Material]) -> Option<Vec<u8>> {
    let pbr: Vec<(usize, &Pbr)> = materials
        .iter()
        .enumerate()
        .filter_map(|(i, m)| m.pbr.as_ref().map(|p| (i, p)))
        .collect();
    let photo: Vec<(usize, &Photometric)> = lights
        .iter()
        .enumerate()
        .filter_map(|(i, l)| l.photometric.as_ref().map(|p| (i, p)))
        .collect();
    if pbr.is_empty() && photo.is_empty() {
        return None;
    }
    let mut e = Enc::default();
    e.u32(pbr.len() as u32);
    for (i, p) in pbr {
        e.u32(i as u32);
        for x in [
            p.metallic,
            p.roughness,
            p.emissive[0],
            p.emissive[1],
            p.emissive[2],
        ] {
            e.f32(x);
        }
    }
    e.u32(photo.len() as u32);
    for (i, p) in photo {
        e.u32(i as u32);
        e.u32(p.kind as u32);
        e.f32(p.intensity);
        e.f32(p.range.unwrap_or(0.0));
        e.f32(p.inner_cone);
        e.f32(p.outer_cone);
        for x in p.direction {
            e.f64(x);
        }
    }
    Some(e.0)
}

/// Reads the appearance table into the materials and lights it names.
fn decode_appearance(
    d: &mut Dec<'_>,
    lights: &mut [Light],
    materials: &mut [Material],
) -> Option<()> {
    let finite = |x: f32| x.is_finite().then_some(x);
    indexed_entries(d, materials.len(), PBR_ENTRY, |d, i| {
        let metallic = finite(d.f32()?)?;
        let roughness = finite(d.f32()?)?;
        let emissive = [finite(d.f32()?)?, finite(d.f32()?)?, finite(d.f32()?)?];
        materials.get_mut(i)?.pbr = Some(Pbr {
            metallic,
            roughness,
            emissive,
        });
        Some(())
    })?;
    indexed_entries(d, lights.len(), LIGHT_ENTRY, |d, i| {
        let kind = match d.u32()? {
            0 => LightKind::Point,
            1 => LightKind::Spot,
            2 => LightKind::Directional,
            _ => return None,
        };
        let intensity = finite(d.f32()?)?;
        let range = finite(d.f32()?)?;
        let inner_cone = finite(d.f32()?)?;
        let outer_cone = finite(d.f32()?)?;
        let direction = [d.f64()?, d.f64()?, d.f64()?];
        if !direction.iter().all(|x| x.is_finite()) {
            return None;
        }
        lights.get_mut(i)?.photometric = Some(Photometric {
            kind,
            intensity,
            range: (range > 0.0).then_some(range),
            inner_cone,
            outer_cone,
            direction,
        });
        Some(())
    })
}

/// Bytes of one material's texture entry.
const TEXTURE_ENTRY: usize = 4 * 10;

/// The texture part of the appearance table (version 8): each textured
/// material's binding (image, sampler, transform), then the images, each
/// its name and its bytes as the file gave them (PNG or JPEG). Version 9
/// ([`encode_tiled_images`]) lists tiles instead of bytes.
pub(super) fn encode_bindings(materials: &[Material]) -> Vec<u8> {
    let mut e = Enc::default();
    let bound: Vec<(usize, &TextureBinding)> = materials
        .iter()
        .enumerate()
        .filter_map(|(i, m)| m.texture.as_ref().map(|t| (i, t)))
        .collect();
    e.u32(bound.len() as u32);
    for (i, t) in bound {
        e.u32(i as u32);
        put_binding(&mut e, t);
    }
    // Version 9: the other maps, each by 3 x material + slot.
    let maps: Vec<(usize, TextureBinding)> = materials
        .iter()
        .enumerate()
        .flat_map(|(i, m)| {
            m.maps
                .slots()
                .into_iter()
                .filter_map(move |(slot, b)| b.map(|b| (3 * i + slot as usize, b)))
        })
        .collect();
    e.u32(maps.len() as u32);
    for (k, t) in maps {
        e.u32(k as u32);
        put_binding(&mut e, &t);
    }
    e.0
}

/// One binding's entry after its index: image, sampler, transform,
/// cut-off and alpha.
fn put_binding(e: &mut Enc, t: &TextureBinding) {
    e.u32(t.image);
    let s = &t.sampler;
    e.u32(s.wrap_s as u32 | (s.wrap_t as u32) << 4 | (s.filter as u32) << 8);
    for x in [
        t.transform.offset[0],
        t.transform.offset[1],
        t.transform.rotation,
        t.transform.scale[0],
        t.transform.scale[1],
        t.cutoff,
        t.alpha,
    ] {
        e.f32(x);
    }
}

/// Reads what [`put_binding`] wrote.
fn get_binding(d: &mut Dec<'_>) -> Option<TextureBinding> {
    let wrap = |c: u32| match c {
        0 => Some(Wrap::Repeat),
        1 => Some(Wrap::ClampToEdge),
        2 => Some(Wrap::MirroredRepeat),
        _ => None,
    };
    let finite = |x: f32| x.is_finite().then_some(x);
    let image = d.u32()?;
    let s = d.u32()?;
    if s >> 12 != 0 {
        return None;
    }
    let sampler = Sampler {
        wrap_s: wrap(s & 15)?,
        wrap_t: wrap(s >> 4 & 15)?,
        filter: match s >> 8 & 15 {
            0 => Filter::Nearest,
            1 => Filter::Linear,
            _ => return None,
        },
    };
    let mut v = [0f32; 7];
    for x in &mut v {
        *x = finite(d.f32()?)?;
    }
    Some(TextureBinding {
        image,
        sampler,
        transform: UvTransform {
            offset: [v[0], v[1]],
            rotation: v[2],
            scale: [v[3], v[4]],
        },
        cutoff: v[5],
        alpha: v[6],
    })
}

/// Bytes of one tile's entry: its offset, stored size and CRC-32.
const TILE_ENTRY: usize = 16;
/// Bytes of an image's entry besides its name and tiles.
const TILED_IMAGE_ENTRY: usize = 4 * 5;
/// The widest and tallest image a database holds.
pub const MAX_IMAGE_SIDE: u32 = 1 << 17;

/// The images of a version 9 database: where the tiles' section lies,
/// then each image's name, size, encoding and tiles.
pub(super) fn encode_tiled_images(section: TilesSection, images: &[TextureImage]) -> Vec<u8> {
    let mut e = Enc::default();
    e.u64(section.offset);
    e.u64(section.bytes);
    e.u32(images.len() as u32);
    for im in images {
        let ImageData::Tiled(t) = &im.data else {
            unreachable!("the writer tiles every image before the tables");
        };
        e.u32(im.name.len() as u32);
        e.0.extend_from_slice(im.name.as_bytes());
        e.u32(t.width);
        e.u32(t.height);
        e.u32(t.encoding as u32);
        e.u32(t.tiles.len() as u32);
        for r in &t.tiles {
            e.u64(r.offset);
            e.u32(r.stored);
            e.u32(r.crc);
        }
    }
    e.0
}

/// Reads the images of a version 9 database: every tile inside the
/// tiles' section, as many as the image's mip chain has.
fn decode_tiled_images(d: &mut Dec<'_>) -> Option<(Vec<TextureImage>, TilesSection)> {
    let section = TilesSection {
        offset: d.u64()?,
        bytes: d.u64()?,
    };
    let end = section.offset.checked_add(section.bytes)?;
    let n = d.u32()? as usize;
    if n > MAX_IMAGES || n * (4 + TILED_IMAGE_ENTRY) > d.remaining() {
        return None;
    }
    let mut images = Vec::with_capacity(n);
    for _ in 0..n {
        let len = d.u32()? as usize;
        let name = String::from_utf8(d.bytes(len)?.to_vec()).ok()?;
        let (width, height) = (d.u32()?, d.u32()?);
        let encoding = match d.u32()? {
            0 => Encoding::Srgb,
            1 => Encoding::Linear,
            _ => return None,
        };
        let count = d.u32()? as usize;
        if width > MAX_IMAGE_SIDE
            || height > MAX_IMAGE_SIDE
            || crate::texture::mip::levels(width, height)?.1 as usize != count
            || count * TILE_ENTRY > d.remaining()
        {
            return None;
        }
        let mut tiles = Vec::with_capacity(count);
        for _ in 0..count {
            let r = TileRef {
                offset: d.u64()?,
                stored: d.u32()?,
                crc: d.u32()?,
            };
            let tile_end = r.offset.checked_add(r.stored as u64)?;
            if r.offset < section.offset
                || tile_end > end
                || r.stored as usize > max_stored(crate::texture::mip::TILE_BYTES)
            {
                return None;
            }
            tiles.push(r);
        }
        images.push(TextureImage {
            name,
            data: ImageData::Tiled(TiledImage {
                width,
                height,
                encoding,
                tiles,
            }),
        });
    }
    Some((images, section))
}

/// Reads the materials' texture bindings into the materials they name;
/// `maps` (version 9): then their other maps.
fn decode_bindings(d: &mut Dec<'_>, materials: &mut [Material], maps: bool) -> Option<()> {
    indexed_entries(d, materials.len(), TEXTURE_ENTRY, |d, i| {
        materials.get_mut(i)?.texture = Some(get_binding(d)?);
        Some(())
    })?;
    if maps {
        indexed_entries(d, 3 * materials.len(), TEXTURE_ENTRY, |d, k| {
            let b = get_binding(d)?;
            *materials.get_mut(k / 3)?.maps.slot_mut((k % 3) as u32)? = Some(b);
            Some(())
        })?;
    }
    Some(())
}

/// Reads the images of a version 8 database (names and bytes).
fn decode_images(d: &mut Dec<'_>) -> Option<Vec<TextureImage>> {
    let n = d.u32()? as usize;
    if n > MAX_IMAGES || n * 12 > d.remaining() {
        return None;
    }
    let mut images = Vec::with_capacity(n);
    let mut total = 0u64;
    for _ in 0..n {
        let len = d.u32()? as usize;
        let name = String::from_utf8(d.bytes(len)?.to_vec()).ok()?;
        let len = d.u64()?;
        total = total.checked_add(len)?;
        if total > MAX_IMAGE_BYTES {
            return None;
        }
        let bytes = d.bytes(usize::try_from(len).ok()?)?.to_vec();
        images.push(TextureImage::encoded(name, bytes));
    }
    // Bindings are checked against the images by the database that holds
    // them (a model's materials bind the world's images).
    Some(images)
}

/// A count, then that many entries of `entry` bytes each, each led by an
/// index below `max` larger than the one before; `read` decodes the rest
/// of entry `i`. `None` on a count or index out of range.
fn indexed_entries(
    d: &mut Dec<'_>,
    max: usize,
    entry: usize,
    mut read: impl FnMut(&mut Dec<'_>, usize) -> Option<()>,
) -> Option<()> {
    let n = d.u32()? as usize;
    if n > max || n * entry > d.remaining() {
        return None;
    }
    let mut last = None;
    for _ in 0..n {
        let i = d.u32()? as usize;
        if last.is_some_and(|l| i <= l) {
            return None;
        }
        last = Some(i);
        read(d, i)?;
    }
    Some(())
}
