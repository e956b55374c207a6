//! Material libraries of OBJ files (`.mtl`), mapped to NFF's material
//! model (colour, Kd, Ks, shine, T, ior):
//!
//! | MTL | NFF |
//! |---|---|
//! | `Kd r g b` | colour `r g b`, Kd 1 (the product is what NFF's diffuse term uses) |
//! | `Ks r g b` with `illum` 3 to 9 (ray-traced reflection on) | Ks = mean of r, g, b |
//! | `Ks` with `illum` 0, 1, 2 or none | Ks 0: NFF's Ks is the mirror reflection as well as the highlight, and a highlight-only material would turn into a mirror |
//! | `Ns` | shine (0 to 1000) |
//! | `d` (dissolve) | T = 1 - d |
//! | `Tr` | T = Tr (the same thing, inverted; `d` wins if both are given) |
//! | `Ni` | ior (1 if absent) |
//!
//! `map_Kd` names the diffuse texture (an image beside the library),
//! which multiplies `Kd` where faces have texture coordinates; its
//! `-clamp on` clamps instead of repeating, `-o` and `-s` offset and scale
//! the coordinates, and other options are ignored.
//!
//! A material without `Kd` takes the neutral grey of meshes without
//! materials. Ambient, emissive, other texture maps and the rest are
//! ignored.

use super::NEUTRAL;
use super::text::{LineReader, real, shown, words};
use crate::error::Error;
use crate::input::Wrapping;
use crate::scene::Material;
use crate::texture::{Filter, Sampler, UvTransform, Wrap};
use std::io::BufRead;
use std::path::Path;

/// Most materials one library may define.
pub const MAX_LIBRARY_MATERIALS: usize = 1 << 16;

#[derive(Default)]
struct Partial {
    kd: Option<[f32; 3]>,
    ks: Option<[f32; 3]>,
    ns: Option<f32>,
    ni: Option<f32>,
    d: Option<f32>,
    tr: Option<f32>,
    illum: Option<i64>,
    map_kd: Option<MapKd>,
}

/// A material's `map_Kd`: the image's file name (relative to the
/// library's directory) and how it is sampled.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct MapKd {
    pub file: String,
    pub sampler: Sampler,
    pub transform: UvTransform,
}

/// Arguments each `map_Kd` option takes (at most; `-o`, `-s` and `-t`
/// take one to three numbers).
fn option_args(o: &[u8]) -> Option<usize> {
    Some(match o {
        b"-blendu" | b"-blendv" | b"-bm" | b"-boost" | b"-cc" | b"-clamp" | b"-imfchan"
        | b"-texres" | b"-type" => 1,
        b"-mm" => 2,
        b"-o" | b"-s" | b"-t" => 3,
        _ => return None,
    })
}

/// Parses the words after `map_Kd`: options, then the file name (which
/// may hold spaces).
fn map_kd(rest: &[&[u8]], warn: &mut dyn FnMut(&str)) -> Option<MapKd> {
    let mut clamp = false;
    let (mut offset, mut scale) = ([0f32; 2], [1f32; 2]);
    let mut i = 0;
    while i < rest.len() && rest[i].starts_with(b"-") {
        let o = rest[i];
        let Some(n) = option_args(o) else {
            warn("unknown map_Kd options ignored");
            i += 1;
            continue;
        };
        i += 1;
        let mut args = Vec::new();
        while args.len() < n && i < rest.len() {
            match real(rest[i]) {
                Ok(v) if n == 3 => args.push(v as f32),
                _ if n == 3 => break,
                _ => args.push(0.0),
            }
            if o == b"-clamp" {
                clamp = rest[i] == b"on";
            }
            i += 1;
        }
        match o {
            b"-o" => {
                offset = [
                    args.first().copied().unwrap_or(0.0),
                    args.get(1).copied().unwrap_or(0.0),
                ]
            }
            b"-s" => {
                scale = [
                    args.first().copied().unwrap_or(1.0),
                    args.get(1).copied().unwrap_or(1.0),
                ]
            }
            b"-clamp" => {}
            _ => warn("map_Kd options other than -clamp, -o and -s ignored"),
        }
    }
    let file = rest[i.min(rest.len())..]
        .iter()
        .map(|w| String::from_utf8_lossy(w))
        .collect::<Vec<_>>()
        .join(" ");
    if file.is_empty() {
        warn("a map_Kd without a file name ignored");
        return None;
    }
    let wrap = if clamp {
        Wrap::ClampToEdge
    } else {
        Wrap::Repeat
    };
    // OBJ's v runs up the image, sray's (glTF's) down it: v' = s v + o in
    // OBJ's terms is v' = s v + (1 - s - o) in sray's.
    let transform = UvTransform {
        offset: [offset[0], 1.0 - scale[1] - offset[1]],
        rotation: 0.0,
        scale,
    };
    Some(MapKd {
        file,
        sampler: Sampler {
            wrap_s: wrap,
            wrap_t: wrap,
            filter: Filter::Linear,
        },
        transform: if transform
            == (UvTransform {
                offset: [0.0; 2],
                rotation: 0.0,
                scale: [1.0; 2],
            }) {
            UvTransform::default()
        } else {
            transform
        },
    })
}

impl Partial {
    fn material(&self) -> Material {
        let reflect = matches!(self.illum, Some(3..=9));
        let ks = match (reflect, self.ks) {
            (true, Some(k)) => (k[0] + k[1] + k[2]) / 3.0,
            _ => 0.0,
        };
        let t = match (self.d, self.tr) {
            (Some(d), _) => 1.0 - d,
            (None, Some(tr)) => tr,
            _ => 0.0,
        };
        Material {
            pbr: None,
            texture: None,
            maps: crate::scene::Maps::NONE,
            color: self.kd.unwrap_or(NEUTRAL.color),
            kd: 1.0,
            ks: ks.clamp(0.0, 1.0),
            shine: self.ns.unwrap_or(0.0).clamp(0.0, 1000.0),
            t: t.clamp(0.0, 1.0),
            ior: self.ni.unwrap_or(1.0),
        }
    }
}

/// A library's material: its name, the material, its diffuse texture.
pub(crate) type MtlEntry = (String, Material, Option<MapKd>);

/// Reads a material library: its materials by name, in file order.
pub(crate) fn read_mtl<R: BufRead>(
    src: R,
    name: &Path,
    warn: &mut dyn FnMut(&str, u64),
) -> Result<Vec<MtlEntry>, Error> {
    let mut lines = LineReader::new(src, name, Wrapping::Plain, 64 << 10);
    let mut out: Vec<MtlEntry> = Vec::new();
    let mut cur: Option<(String, Partial)> = None;
    let mut line: Vec<u8> = Vec::new();
    while let Some(l) = lines.next_line()? {
        line.clear();
        line.extend_from_slice(l);
        let l = match line.iter().position(|&b| b == b'#') {
            Some(i) => &line[..i],
            None => &line[..],
        };
        let mut w = words(l);
        let Some(key) = w.next() else { continue };
        let rest: Vec<&[u8]> = w.collect();
        let nums = |n: usize| -> Result<Vec<f32>, Error> {
            if rest.len() < n {
                return Err(lines.err(format!(
                    "'{}' needs {n} number{}",
                    shown(key),
                    if n > 1 { "s" } else { "" }
                )));
            }
            rest[..n]
                .iter()
                .map(|t| {
                    real(t)
                        .map(|v| v as f32)
                        .map_err(|m| lines.err(m))
                        .and_then(|v| {
                            if v.is_finite() {
                                Ok(v)
                            } else {
                                Err(lines.err("a number beyond single precision"))
                            }
                        })
                })
                .collect()
        };
        let rgb = || -> Result<Option<[f32; 3]>, Error> {
            match rest.first() {
                Some(&b"spectral" | &b"xyz") => Ok(None),
                _ if rest.len() >= 3 => {
                    let v = nums(3)?;
                    Ok(Some([v[0], v[1], v[2]]))
                }
                _ => {
                    let v = nums(1)?;
                    Ok(Some([v[0]; 3]))
                }
            }
        };
        if key == b"newmtl" {
            if let Some((n, p)) = cur.take() {
                let m = p.material();
                out.push((n, m, p.map_kd));
            }
            if out.len() >= MAX_LIBRARY_MATERIALS {
                return Err(lines.err(format!(
                    "more than {MAX_LIBRARY_MATERIALS} materials in one library"
                )));
            }
            let name = String::from_utf8_lossy(l.trim_ascii()[6..].trim_ascii()).into_owned();
            cur = Some((name, Partial::default()));
            continue;
        }
        let Some((_, p)) = cur.as_mut() else {
            warn("statements before the first 'newmtl' ignored", lines.line());
            continue;
        };
        match key {
            b"Kd" => match rgb()? {
                Some(c) => p.kd = Some(c),
                None => warn("spectral and CIEXYZ colours ignored", lines.line()),
            },
            b"Ks" => match rgb()? {
                Some(c) => p.ks = Some(c),
                None => warn("spectral and CIEXYZ colours ignored", lines.line()),
            },
            b"Ns" => p.ns = Some(nums(1)?[0]),
            b"Ni" => p.ni = Some(nums(1)?[0]),
            b"d" => {
                // `d -halo 0.5`: the factor is the last word.
                let v = rest
                    .last()
                    .ok_or_else(|| lines.err("'d' needs a number"))
                    .and_then(|t| real(t).map_err(|m| lines.err(m)))?;
                p.d = Some(v as f32);
            }
            b"Tr" => p.tr = Some(nums(1)?[0]),
            b"illum" => {
                let v = nums(1)?[0];
                p.illum = Some(v as i64);
            }
            b"map_Kd" => {
                let at = lines.line();
                p.map_kd = map_kd(&rest, &mut |w| warn(w, at));
            }
            _ => {}
        }
    }
    if let Some((n, p)) = cur.take() {
        let m = p.material();
        out.push((n, m, p.map_kd));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn materials_map_to_nff() {
        let text = b"# a library\nnewmtl red\nKd 1 0 0\nKs 0.5 0.5 0.5\nNs 50\nillum 2\n\
newmtl mirror\nKd 0.1 0.1 0.1\nKs 0.9 0.6 0.3\nillum 3\nNs 200\n\
newmtl glass\nKd 1 1 1\nd 0.25\nNi 1.5\nillum 7\n\
newmtl grey\nKd 0.5\nTr 0.1\n\
newmtl bare\n";
        let mut warned = Vec::new();
        let m = read_mtl(&text[..], Path::new("t.mtl"), &mut |w, l| {
            warned.push((w.to_string(), l))
        })
        .unwrap();
        assert_eq!(m.len(), 5);
        assert_eq!(m[0].0, "red");
        assert_eq!(
            m[0].1,
            Material {
                pbr: None,
                texture: None,
                maps: crate::scene::Maps::NONE,
                color: [1.0, 0.0, 0.0],
                kd: 1.0,
                ks: 0.0,
                shine: 50.0,
                t: 0.0,
                ior: 1.0
            }
        );
        assert!((m[1].1.ks - 0.6).abs() < 1e-6 && m[1].1.shine == 200.0);
        assert_eq!((m[2].1.t, m[2].1.ior), (0.75, 1.5));
        assert_eq!(m[3].1.color, [0.5; 3]);
        assert!((m[3].1.t - 0.1).abs() < 1e-6);
        assert_eq!(
            m[4].1,
            Material {
                pbr: None,
                texture: None,
                maps: crate::scene::Maps::NONE,
                ior: 1.0,
                ..NEUTRAL
            }
        );
        assert!(warned.is_empty());
        let e = read_mtl(
            &b"newmtl a\nKd 1 x 0\n"[..],
            Path::new("t.mtl"),
            &mut |_, _| {},
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("t.mtl:2:"), "{e}");
    }
}
