//! A glTF file's document and buffers, read within a memory budget.
//!
//! Only the JSON document, and buffers embedded in it as data URIs, are
//! held whole. A `.glb`'s binary chunk and a `.gltf`'s external buffer
//! files are read where they lie: an accessor's elements in chunks when
//! they are read in order (positions for the bounds, indices, a
//! primitive's vertices), or a few at a time through a small page cache
//! (a vertex looked up by index when a primitive's vertices do not fit in
//! memory). So a file of any size converts in bounded memory; only its
//! document must fit.
//!
//! Every range is checked against the buffer before it is read: an
//! accessor, a view or a chunk past its data is an error naming it, never
//! a panic or an allocation by a count the file does not back.

use base64::Engine as _;
use gltf::accessor::{DataType, Dimensions};
use std::collections::HashMap;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

/// Bytes of one cached page of a buffer file.
const PAGE: usize = 64 << 10;

/// Bytes a JSON object takes once parsed, about (gltf-json's node,
/// accessor and primitive structs, with their maps and vectors).
const PARSED_OBJECT: u64 = 512;

/// Bytes an in-order read takes at a time.
const CHUNK: usize = 1 << 20;

/// Where the bytes of a glTF file itself are: in memory (the fuzzer's and
/// tests' way in) or in a file read by offset.
pub(super) enum Main<'a> {
    Slice(&'a [u8]),
    File(File),
}

impl Main<'_> {
    fn len(&self) -> std::io::Result<u64> {
        match self {
            Main::Slice(s) => Ok(s.len() as u64),
            Main::File(f) => Ok(f.metadata()?.len()),
        }
    }

    fn read_at(&mut self, at: u64, out: &mut [u8]) -> std::io::Result<()> {
        match self {
            Main::Slice(s) => {
                let src = usize::try_from(at)
                    .ok()
                    .and_then(|a| s.get(a..a.checked_add(out.len())?))
                    .ok_or(std::io::ErrorKind::UnexpectedEof)?;
                out.copy_from_slice(src);
                Ok(())
            }
            Main::File(f) => {
                f.seek(SeekFrom::Start(at))?;
                f.read_exact(out)
            }
        }
    }
}

/// The bytes of a glTF file's buffers.
pub(super) struct Buffers<'a> {
    data: Vec<Data<'a>>,
    pages: Pages,
    /// Reused by in-order reads.
    scratch: Vec<u8>,
    /// Bytes read from files so far (for progress).
    pub read: u64,
}

/// Where one buffer's bytes are.
enum Data<'a> {
    Slice(&'a [u8]),
    Owned(Vec<u8>),
    File { file: File, start: u64, len: u64 },
}

impl Data<'_> {
    fn len(&self) -> u64 {
        match self {
            Data::Slice(s) => s.len() as u64,
            Data::Owned(v) => v.len() as u64,
            Data::File { len, .. } => *len,
        }
    }
}

const GLB_JSON: u32 = 0x4E4F_534A;
const GLB_BIN: u32 = 0x004E_4942;

/// The document of the glTF file in `main` (`.glb` or `.gltf`), held
/// within `doc_budget` bytes with its data-URI buffers, and where its
/// other buffers are (external ones under `base`). `cache` bytes of pages
/// are kept for reads by index. Also the extensions the file requires
/// that are ignored (see [`parse_document`]).
pub(super) fn open<'a>(
    mut main: Main<'a>,
    base: Option<&Path>,
    doc_budget: u64,
    cache: u64,
) -> Result<(gltf::Document, Buffers<'a>, Vec<String>), String> {
    let io = |e: std::io::Error| format!("cannot read it: {e}");
    let file_len = main.len().map_err(io)?;
    let mut head = [0u8; 12];
    let is_glb = file_len >= 4 && {
        main.read_at(0, &mut head[..4]).map_err(io)?;
        &head[..4] == b"glTF"
    };
    let (json, bin) = if is_glb {
        glb_chunks(&mut main, file_len, doc_budget)?
    } else {
        if file_len > doc_budget {
            return Err(too_big("its JSON document", file_len, doc_budget));
        }
        let mut json = vec![0u8; file_len as usize];
        main.read_at(0, &mut json).map_err(io)?;
        (json, None)
    };
    // Parsed, each JSON object becomes a struct of a few hundred bytes:
    // judged before parsing, so that a document of many small objects
    // cannot take many times its size.
    let objects = json.iter().filter(|&&c| c == b'{').count() as u64;
    let parsed = (json.len() as u64).saturating_add(objects.saturating_mul(PARSED_OBJECT));
    if parsed > doc_budget {
        return Err(too_big(
            &format!("its JSON document, parsed ({objects} objects),"),
            parsed,
            doc_budget,
        ));
    }
    let (doc, ignored) = parse_document(&json)?;
    // The document, parsed, keeps its data URIs' text: it counts with
    // their bytes.
    let mut held = parsed;
    drop(json);
    let mut data = Vec::with_capacity(doc.buffers().len());
    for b in doc.buffers() {
        let i = b.index();
        let d = match b.source() {
            gltf::buffer::Source::Bin => {
                let (start, len) = bin.ok_or_else(|| {
                    format!("buffer {i} is the GLB's binary chunk, which the file lacks")
                })?;
                match &main {
                    Main::Slice(s) => Data::Slice(&s[start as usize..(start + len) as usize]),
                    Main::File(f) => Data::File {
                        file: f.try_clone().map_err(io)?,
                        start,
                        len,
                    },
                }
            }
            gltf::buffer::Source::Uri(uri) => match uri.strip_prefix("data:") {
                Some(rest) => {
                    let bytes = data_uri(rest).map_err(|e| format!("buffer {i}: {e}"))?;
                    held += bytes.len() as u64;
                    if held > doc_budget {
                        return Err(too_big(
                            "its buffers embedded as data URIs",
                            held,
                            doc_budget,
                        ));
                    }
                    Data::Owned(bytes)
                }
                None => {
                    let path = buffer_path(uri, base).map_err(|e| format!("buffer {i}: {e}"))?;
                    let file = File::open(&path)
                        .map_err(|e| format!("buffer {i}: cannot open {}: {e}", path.display()))?;
                    let len = file
                        .metadata()
                        .map_err(|e| format!("buffer {i}: {}: {e}", path.display()))?
                        .len();
                    Data::File {
                        file,
                        start: 0,
                        len,
                    }
                }
            },
        };
        let declared = b.length() as u64;
        if d.len() < declared {
            return Err(format!(
                "buffer {i} holds {} bytes of the {declared} it declares",
                d.len(),
            ));
        }
        // Accessors and views may use the declared bytes only (a GLB's
        // binary chunk is padded; a file may hold more).
        data.push(match d {
            Data::Slice(s) => Data::Slice(&s[..declared as usize]),
            Data::Owned(mut v) => {
                v.truncate(declared as usize);
                Data::Owned(v)
            }
            Data::File { file, start, .. } => Data::File {
                file,
                start,
                len: declared,
            },
        });
    }
    let pages = Pages::new((cache / PAGE as u64).clamp(16, 1 << 20) as usize);
    Ok((
        doc,
        Buffers {
            data,
            pages,
            scratch: Vec::new(),
            read: 0,
        },
        ignored,
    ))
}

fn too_big(what: &str, bytes: u64, budget: u64) -> String {
    format!(
        "{what} takes {}, more than the {} of the memory budget it may hold whole (raise --memory)",
        crate::units::fmt_bytes(bytes),
        crate::units::fmt_bytes(budget)
    )
}

/// A GLB's JSON chunk (read) and its binary chunk (where it lies).
#[allow(clippy::type_complexity)]
fn glb_chunks(
    main: &mut Main<'_>,
    file_len: u64,
    doc_budget: u64,
) -> Result<(Vec<u8>, Option<(u64, u64)>), String> {
    let short = || "a GLB shorter than its header says".to_string();
    let mut head = [0u8; 12];
    main.read_at(0, &mut head).map_err(|_| short())?;
    let word = |b: &[u8], k: usize| u32::from_le_bytes(b[4 * k..4 * k + 4].try_into().unwrap());
    if word(&head, 1) != 2 {
        return Err(format!("GLB version {} (only 2 is read)", word(&head, 1)));
    }
    let total = u64::from(word(&head, 2));
    if total > file_len {
        return Err(format!(
            "the GLB says it is {total} bytes; the file has {file_len}"
        ));
    }
    let mut json = None;
    let mut bin = None;
    let mut at = 12u64;
    while at + 8 <= total {
        let mut ch = [0u8; 8];
        main.read_at(at, &mut ch).map_err(|_| short())?;
        let (len, kind) = (u64::from(word(&ch, 0)), word(&ch, 1));
        let start = at + 8;
        if start + len > total {
            return Err(format!("a GLB chunk at byte {at} ends past the file"));
        }
        match kind {
            GLB_JSON if json.is_none() => {
                if len > doc_budget {
                    return Err(too_big("its JSON document", len, doc_budget));
                }
                let mut j = vec![0u8; len as usize];
                main.read_at(start, &mut j).map_err(|_| short())?;
                json = Some(j);
            }
            GLB_BIN if json.is_some() && bin.is_none() => bin = Some((start, len)),
            _ => {}
        }
        at = start + len;
    }
    let json = json.ok_or_else(|| "a GLB without a JSON chunk".to_string())?;
    Ok((json, bin))
}

/// Extensions read here (the gltf crate's validation knows only some).
const READ: [&str; 7] = [
    "EXT_mesh_gpu_instancing",
    "KHR_mesh_quantization",
    "KHR_lights_punctual",
    "KHR_materials_transmission",
    "KHR_materials_ior",
    "KHR_texture_transform",
    "KHR_materials_emissive_strength",
];

/// Extensions without which a file's geometry cannot be read.
const GEOMETRY: [&str; 3] = [
    "KHR_draco_mesh_compression",
    "EXT_meshopt_compression",
    "KHR_meshopt_compression",
];

/// The glTF document of `json`, validated, and the extensions it requires
/// that are ignored.
///
/// - `extensionsRequired` is judged here: an extension this reader reads
///   is fine; one that compresses the geometry is an error; any other
///   (textures, material extensions) is ignored, returned for a warning:
///   the shapes are right, the shading may differ.
/// - gltf-json 1.4.1's validation indexes a primitive's POSITION accessor
///   before checking that it exists (a panic on a bad file): that is
///   checked first, as is gltf 1.4.1's `Image::source`, which unwraps a
///   buffer-view image's `mimeType` and an image's `uri` when it has no
///   buffer view (the specification requires them).
fn parse_document(json: &[u8]) -> Result<(gltf::Document, Vec<String>), String> {
    let invalid = |e: gltf::Error| format!("not a valid glTF file: {e}");
    let mut root = gltf::Gltf::from_slice_without_validation(json)
        .map_err(invalid)?
        .document
        .into_json();
    let mut ignored = Vec::new();
    for ext in std::mem::take(&mut root.extensions_required) {
        if GEOMETRY.contains(&ext.as_str()) {
            return Err(format!(
                "its geometry is compressed with {ext}, which sray does not decode \
                 (write the file without it, e.g. with gltf-transform or gltfpack)"
            ));
        }
        if !READ.contains(&ext.as_str()) {
            ignored.push(ext);
        }
    }
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (k, prim) in mesh.primitives.iter().enumerate() {
            for a in prim.attributes.values() {
                if a.value() >= root.accessors.len() {
                    return Err(format!(
                        "mesh {m} primitive {k}: an attribute names accessor {}, of {}",
                        a.value(),
                        root.accessors.len()
                    ));
                }
            }
        }
    }
    for (i, image) in root.images.iter().enumerate() {
        match (&image.buffer_view, &image.uri) {
            (Some(_), _) if image.mime_type.is_none() => {
                return Err(format!(
                    "image {i} lies in a buffer view but has no mimeType (image/png or image/jpeg)"
                ));
            }
            (None, None) => {
                return Err(format!("image {i} has neither a bufferView nor a uri"));
            }
            _ => {}
        }
    }
    Ok((gltf::Document::from_json(root).map_err(invalid)?, ignored))
}

/// The bytes of image `image` (PNG or JPEG, as the file holds them): from
/// its buffer view, a data URI or a file beside the glTF's (`base` its
/// directory); at most `budget` bytes.
pub(super) fn image_bytes(
    image: &gltf::Image<'_>,
    bufs: &mut Buffers<'_>,
    base: Option<&Path>,
    budget: u64,
) -> Result<Vec<u8>, String> {
    let i = image.index();
    let too_big =
        |n: u64| format!("image {i}: {n} bytes, more than the {budget} this render may hold");
    match image.source() {
        gltf::image::Source::View { view, .. } => {
            let n = view.length() as u64;
            if n > budget {
                return Err(too_big(n));
            }
            let b = view.buffer().index();
            let mut out = vec![0u8; view.length()];
            bufs.read(b, view.offset() as u64, &mut out)
                .map_err(|e| format!("image {i}: {e}"))?;
            Ok(out)
        }
        gltf::image::Source::Uri { uri, .. } => match uri.strip_prefix("data:") {
            Some(rest) => data_uri(rest).map_err(|e| format!("image {i}: {e}")),
            None => {
                let path = buffer_path(uri, base).map_err(|e| format!("image {i}: {e}"))?;
                let n = std::fs::metadata(&path)
                    .map_err(|e| format!("image {i}: cannot open {}: {e}", path.display()))?
                    .len();
                if n > budget {
                    return Err(too_big(n));
                }
                std::fs::read(&path)
                    .map_err(|e| format!("image {i}: cannot read {}: {e}", path.display()))
            }
        },
    }
}

/// The bytes of a base64 data URI (what follows `data:`).
fn data_uri(rest: &str) -> Result<Vec<u8>, String> {
    let (_, payload) = rest
        .split_once(";base64,")
        .ok_or("a data URI that is not base64")?;
    base64::engine::general_purpose::STANDARD
        .decode(payload)
        .map_err(|e| format!("a data URI that is not valid base64: {e}"))
}

/// The file a buffer's URI names: a relative path (percent-decoded) under
/// `base`, or a `file:` URI.
fn buffer_path(uri: &str, base: Option<&Path>) -> Result<PathBuf, String> {
    let rel = match uri.split_once(':') {
        None => uri,
        Some(("file", rest)) => rest.strip_prefix("//").unwrap_or(rest),
        Some((scheme, _)) => {
            return Err(format!(
                "a {scheme}: URI (only relative paths, file: and data: URIs are read)"
            ));
        }
    };
    let decoded = percent_decode(rel).ok_or("its URI is not UTF-8 once decoded")?;
    let p = PathBuf::from(decoded);
    Ok(match base {
        Some(b) if p.is_relative() => b.join(p),
        Some(_) => p,
        None => {
            return Err(format!(
                "{uri} is outside the file (no directory to look in)"
            ));
        }
    })
}

/// `%XX` escapes decoded, if that gives UTF-8.
fn percent_decode(uri: &str) -> Option<String> {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        match (
            b[i],
            b.get(i + 1).copied().and_then(hex),
            b.get(i + 2).copied().and_then(hex),
        ) {
            (b'%', Some(h), Some(l)) => {
                out.push((h * 16 + l) as u8);
                i += 3;
            }
            (c, ..) => {
                out.push(c);
                i += 1;
            }
        }
    }
    String::from_utf8(out).ok()
}

impl Buffers<'_> {
    /// Bytes buffer `b` holds (0 for a buffer the file does not have).
    pub fn len(&self, b: usize) -> u64 {
        self.data.get(b).map_or(0, Data::len)
    }

    /// Reads `out.len()` bytes of buffer `b` from byte `at`: directly when
    /// it is a large in-order read, else through the page cache.
    fn read(&mut self, b: usize, at: u64, out: &mut [u8]) -> Result<(), String> {
        let end = at.checked_add(out.len() as u64);
        let data = self
            .data
            .get_mut(b)
            .ok_or_else(|| format!("buffer {b} is missing"))?;
        if end.is_none_or(|e| e > data.len()) {
            return Err(format!("a read past buffer {b}'s {} bytes", data.len()));
        }
        let io = |e: std::io::Error| format!("cannot read buffer {b}: {e}");
        match data {
            Data::Slice(s) => out.copy_from_slice(&s[at as usize..][..out.len()]),
            Data::Owned(v) => out.copy_from_slice(&v[at as usize..][..out.len()]),
            Data::File { file, start, len } => {
                self.read += out.len() as u64;
                if out.len() >= PAGE {
                    file.seek(SeekFrom::Start(*start + at)).map_err(io)?;
                    file.read_exact(out).map_err(io)?;
                    return Ok(());
                }
                let mut done = 0;
                while done < out.len() {
                    let pos = at + done as u64;
                    let page = pos / PAGE as u64;
                    let (start, len) = (*start, *len);
                    let bytes = self
                        .pages
                        .get((b, page), |buf| {
                            let from = page * PAGE as u64;
                            let n = (len - from).min(PAGE as u64) as usize;
                            file.seek(SeekFrom::Start(start + from))?;
                            file.read_exact(&mut buf[..n])?;
                            Ok(n)
                        })
                        .map_err(io)?;
                    let off = (pos % PAGE as u64) as usize;
                    let n = (bytes.len() - off).min(out.len() - done);
                    out[done..done + n].copy_from_slice(&bytes[off..off + n]);
                    done += n;
                }
            }
        }
        Ok(())
    }
}

/// A few pages of buffer files, evicted by the clock algorithm.
struct Pages {
    cap: usize,
    slots: Vec<Slot>,
    map: HashMap<(usize, u64), usize>,
    hand: usize,
    /// The page last asked for (reads by index come in runs).
    last: Option<((usize, u64), usize)>,
}

struct Slot {
    key: (usize, u64),
    data: Box<[u8]>,
    len: usize,
    referenced: bool,
}

impl Pages {
    fn new(cap: usize) -> Pages {
        Pages {
            cap,
            slots: Vec::new(),
            map: HashMap::new(),
            hand: 0,
            last: None,
        }
    }

    /// The page `key`, loaded by `load` (which returns its length) if it
    /// is not held.
    fn get(
        &mut self,
        key: (usize, u64),
        load: impl FnOnce(&mut [u8]) -> std::io::Result<usize>,
    ) -> std::io::Result<&[u8]> {
        let hit = match self.last {
            Some((k, s)) if k == key => Some(s),
            _ => self.map.get(&key).copied(),
        };
        if let Some(s) = hit {
            self.last = Some((key, s));
            let slot = &mut self.slots[s];
            slot.referenced = true;
            return Ok(&slot.data[..slot.len]);
        }
        let s = if self.slots.len() < self.cap {
            self.slots.push(Slot {
                key,
                data: vec![0u8; PAGE].into_boxed_slice(),
                len: 0,
                referenced: false,
            });
            self.slots.len() - 1
        } else {
            loop {
                let h = self.hand;
                self.hand = (h + 1) % self.slots.len();
                if std::mem::take(&mut self.slots[h].referenced) {
                    continue;
                }
                self.map.remove(&self.slots[h].key);
                self.last = None;
                break h;
            }
        };
        let slot = &mut self.slots[s];
        slot.len = 0;
        slot.len = load(&mut slot.data)?;
        slot.key = key;
        slot.referenced = true;
        self.map.insert(key, s);
        self.last = Some((key, s));
        Ok(&slot.data[..slot.len])
    }
}

/// An accessor's elements, checked to lie within their buffer, read on
/// demand. A sparse accessor's replaced elements are held (sorted by
/// index), its base read like any other.
pub(super) struct Elements {
    index: usize,
    /// Buffer, byte of element 0 in it, and stride; none: zeros (a sparse
    /// accessor without a base).
    view: Option<(usize, u64, u64)>,
    data_type: DataType,
    dims: Dimensions,
    normalized: bool,
    size: usize,
    pub count: usize,
    sparse: Option<(Vec<u32>, Vec<u8>)>,
}

impl Elements {
    /// The elements of `a`, after checking that they lie within their
    /// buffer view and the view within its buffer. A sparse accessor's
    /// replacements are read now, within `budget` bytes.
    pub fn new(
        a: &gltf::Accessor<'_>,
        bufs: &mut Buffers<'_>,
        budget: u64,
    ) -> Result<Elements, String> {
        let size = a.size();
        let count = a.count();
        let index = a.index();
        let sparse = match a.sparse() {
            None => None,
            Some(sp) => {
                // A base (its buffer view, or zeros without one) with
                // `count` elements replaced at the listed indices.
                let n = sp.count();
                if n == 0 || n > count {
                    return Err(format!(
                        "accessor {index}: {n} sparse elements for {count} elements"
                    ));
                }
                let hold = (n as u64).saturating_mul(4 + size as u64);
                if hold > budget {
                    return Err(format!(
                        "accessor {index}: {}",
                        too_big("its sparse elements", hold, budget)
                    ));
                }
                let idx = sp.indices();
                let it = idx.index_type().size();
                let what = format!("accessor {index} sparse indices");
                let (b, at, stride) = place(&idx.view(), bufs, idx.offset(), n, it, &what)?;
                let mut raw = vec![0u8; it];
                let mut indices = Vec::with_capacity(n);
                for k in 0..n {
                    bufs.read(b, at + k as u64 * stride, &mut raw)?;
                    let i = index_of(&raw);
                    if i as usize >= count || indices.last().is_some_and(|&l| l >= i) {
                        return Err(format!(
                            "accessor {index}: sparse index {i} (number {k}) is past {count} \
                             elements or not above the one before"
                        ));
                    }
                    indices.push(i);
                }
                let vals = sp.values();
                let what = format!("accessor {index} sparse values");
                let (b, at, stride) = place(&vals.view(), bufs, vals.offset(), n, size, &what)?;
                let mut values = vec![0u8; n * size];
                for (k, v) in values.chunks_exact_mut(size).enumerate() {
                    bufs.read(b, at + k as u64 * stride, v)?;
                }
                Some((indices, values))
            }
        };
        let view = match a.view() {
            Some(v) => Some(place(
                &v,
                bufs,
                a.offset(),
                count,
                size,
                &format!("accessor {index} ({count} elements)"),
            )?),
            // Zeros nothing in the file backs: as many as the budget
            // could hold, no more (a tiny file must not ask for hours of
            // work).
            None if count == 0 => None,
            None if sparse.is_some() => {
                let zeros = (count as u64).saturating_mul(size as u64);
                if zeros > budget {
                    return Err(format!(
                        "accessor {index}: {}",
                        too_big("a sparse accessor without a buffer view", zeros, budget)
                    ));
                }
                None
            }
            None => return Err(format!("accessor {index} has no buffer view")),
        };
        Ok(Elements {
            index,
            view,
            data_type: a.data_type(),
            dims: a.dimensions(),
            normalized: a.normalized(),
            size,
            count,
            sparse,
        })
    }

    /// Bytes per element.
    pub fn size(&self) -> usize {
        self.size
    }

    /// Elements read at a time in order: about a megabyte of the buffer.
    pub fn per_chunk(&self) -> usize {
        (CHUNK / self.view.map_or(self.size, |v| v.2 as usize).max(1)).max(1)
    }

    /// Checks that the elements are unsigned integer scalars (indices).
    pub fn expect_indices(&self, what: &str) -> Result<(), String> {
        if self.dims != Dimensions::Scalar
            || !matches!(self.data_type, DataType::U8 | DataType::U16 | DataType::U32)
        {
            return Err(format!(
                "{what}: indices (accessor {}) must be unsigned integers",
                self.index
            ));
        }
        Ok(())
    }

    /// Elements `first..first + n` (within `count`), tightly packed, into
    /// `out`.
    fn raw(
        &self,
        bufs: &mut Buffers<'_>,
        first: usize,
        n: usize,
        out: &mut Vec<u8>,
    ) -> Result<(), String> {
        debug_assert!(first + n <= self.count);
        let size = self.size;
        out.clear();
        match self.view {
            None => out.resize(n * size, 0),
            Some(_) if n == 0 => {}
            Some((b, at, stride)) => {
                let span = (n - 1) * stride as usize + size;
                out.resize(span, 0);
                bufs.read(b, at + first as u64 * stride, out)?;
                if stride as usize != size {
                    for k in 1..n {
                        out.copy_within(k * stride as usize..k * stride as usize + size, k * size);
                    }
                    out.truncate(n * size);
                }
            }
        }
        if let Some((idx, vals)) = &self.sparse {
            let from = idx.partition_point(|&i| (i as usize) < first);
            for (j, &i) in idx[from..].iter().enumerate() {
                let i = i as usize;
                if i >= first + n {
                    break;
                }
                let v = &vals[(from + j) * size..][..size];
                out[(i - first) * size..][..size].copy_from_slice(v);
            }
        }
        Ok(())
    }

    /// Elements read in order in chunks of about a megabyte: `each` gets
    /// the first element's number and the chunk's raw bytes.
    pub fn chunks(
        &self,
        bufs: &mut Buffers<'_>,
        mut each: impl FnMut(usize, &[u8]) -> Result<(), String>,
    ) -> Result<(), String> {
        let per = self.per_chunk();
        let mut raw = std::mem::take(&mut bufs.scratch);
        let mut first = 0;
        while first < self.count {
            let n = per.min(self.count - first);
            self.raw(bufs, first, n, &mut raw)?;
            each(first, &raw)?;
            first += n;
        }
        bufs.scratch = raw;
        Ok(())
    }

    /// Indices `first..first + n` (checked by [`Self::expect_indices`])
    /// into `out`.
    pub fn indices(
        &self,
        bufs: &mut Buffers<'_>,
        first: usize,
        n: usize,
        out: &mut Vec<u32>,
    ) -> Result<(), String> {
        let mut raw = std::mem::take(&mut bufs.scratch);
        self.raw(bufs, first, n, &mut raw)?;
        out.clear();
        out.extend(raw.chunks_exact(self.size).map(index_of));
        bufs.scratch = raw;
        Ok(())
    }

    /// Element `k` as three floats (see [`Self::expect_vectors`]): one
    /// read, through the page cache, allocating nothing.
    pub fn vec3(&self, bufs: &mut Buffers<'_>, k: usize) -> Result<[f32; 3], String> {
        self.vec::<3>(bufs, k)
    }

    /// Element `k` as `D` floats (see [`Self::vec3`]).
    pub fn vec<const D: usize>(
        &self,
        bufs: &mut Buffers<'_>,
        k: usize,
    ) -> Result<[f32; D], String> {
        Ok(self.decode::<D>(&self.element(bufs, k)?))
    }

    /// Element `k`'s components (up to four; zeros after them).
    pub fn padded(&self, bufs: &mut Buffers<'_>, k: usize) -> Result<[f32; 4], String> {
        Ok(self.decode_padded(&self.element(bufs, k)?))
    }

    /// The accessor's index in the file.
    pub fn index(&self) -> usize {
        self.index
    }

    /// Components per element (2 for a VEC2, ...).
    pub fn components(&self) -> usize {
        self.dims.multiplicity()
    }

    /// Every element's components (up to four, zeros after them).
    pub fn floats_padded(&self, bufs: &mut Buffers<'_>) -> Result<Vec<[f32; 4]>, String> {
        let mut out = Vec::with_capacity(self.count);
        self.chunks(bufs, |_, raw| {
            out.extend(raw.chunks_exact(self.size).map(|e| self.decode_padded(e)));
            Ok(())
        })?;
        Ok(out)
    }

    /// `e` as [`Self::decode`] reads it, its missing components zero.
    fn decode_padded(&self, e: &[u8]) -> [f32; 4] {
        let n = self.components().min(4);
        let mut out = [0f32; 4];
        match n {
            1 => out[..1].copy_from_slice(&self.decode::<1>(e)),
            2 => out[..2].copy_from_slice(&self.decode::<2>(e)),
            3 => out[..3].copy_from_slice(&self.decode::<3>(e)),
            _ => out = self.decode::<4>(e),
        }
        out
    }

    /// Element `k`'s bytes (its first 16, zeros after it), through the
    /// page cache.
    fn element(&self, bufs: &mut Buffers<'_>, k: usize) -> Result<[u8; 16], String> {
        let mut buf = [0u8; 16];
        let e = &mut buf[..self.size.min(16)];
        if let Some((b, at, stride)) = self.view {
            bufs.read(b, at + k as u64 * stride, e)?;
        }
        if let Some((idx, vals)) = &self.sparse
            && let Ok(j) = idx.binary_search(&(k as u32))
        {
            let n = e.len();
            e.copy_from_slice(&vals[j * self.size..][..n]);
        }
        Ok(buf)
    }

    /// One element's components as floats, as glTF 2.0 (with
    /// `KHR_mesh_quantization`) says: floats as they are; normalized
    /// integers to [0, 1] or [-1, 1]; other integers by value. The
    /// component types were checked by [`Self::expect_vectors`].
    #[inline]
    pub fn decode<const D: usize>(&self, e: &[u8]) -> [f32; D] {
        let (t, norm) = (self.data_type, self.normalized);
        std::array::from_fn(|j| {
            let b = |w: usize| &e[w * j..w * j + w];
            match (t, norm) {
                (DataType::F32, _) => f32::from_le_bytes(b(4).try_into().unwrap()),
                (DataType::I8, true) => (f32::from(e[j] as i8) / 127.0).max(-1.0),
                (DataType::U8, true) => f32::from(e[j]) / 255.0,
                (DataType::I16, true) => {
                    (f32::from(i16::from_le_bytes([e[2 * j], e[2 * j + 1]])) / 32767.0).max(-1.0)
                }
                (DataType::U16, true) => {
                    f32::from(u16::from_le_bytes([e[2 * j], e[2 * j + 1]])) / 65535.0
                }
                (DataType::I8, false) => f32::from(e[j] as i8),
                (DataType::U8, false) => f32::from(e[j]),
                (DataType::I16, false) => f32::from(i16::from_le_bytes([e[2 * j], e[2 * j + 1]])),
                (DataType::U16, false) => f32::from(u16::from_le_bytes([e[2 * j], e[2 * j + 1]])),
                // Not allowed for a vector (refused by `expect_vectors`).
                (DataType::U32, _) => 0.0,
            }
        })
    }

    /// Every element as a vector of `D` floats (see [`Self::decode`]).
    pub fn floats<const D: usize>(&self, bufs: &mut Buffers<'_>) -> Result<Vec<[f32; D]>, String> {
        let mut out = Vec::with_capacity(self.count);
        self.chunks(bufs, |_, raw| {
            out.extend(raw.chunks_exact(self.size).map(|e| self.decode::<D>(e)));
            Ok(())
        })?;
        Ok(out)
    }

    /// Checks that the elements are `dims` of a component type `of`
    /// allows (`true`: normalized).
    pub fn expect_vectors(
        &self,
        dims: Dimensions,
        what: &str,
        of: Components,
    ) -> Result<(), String> {
        let ok = self.dims == dims
            && match (self.data_type, self.normalized) {
                (DataType::F32, false) => true,
                (DataType::I8 | DataType::I16, true) => of != Components::Floats,
                (DataType::U8 | DataType::U16, _) | (DataType::I8 | DataType::I16, false) => {
                    of == Components::Quantized
                }
                _ => false,
            };
        if !ok {
            return Err(format!(
                "accessor {}: {what} must be {dims:?} of {} ({:?}{} found)",
                self.index,
                match of {
                    Components::Floats => "floats",
                    Components::Signed => "floats or normalized signed bytes or shorts",
                    Components::Quantized => "floats, bytes or shorts",
                },
                self.data_type,
                if self.normalized { ", normalized" } else { "" }
            ));
        }
        Ok(())
    }
}

/// The component types a vector may have.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
pub(super) enum Components {
    /// Floats only.
    Floats,
    /// Floats, or normalized signed bytes or shorts (normals, rotations).
    Signed,
    /// Floats, or bytes or shorts of either sign, normalized or not
    /// (positions under `KHR_mesh_quantization`).
    Quantized,
}

/// An index of `size` bytes, little-endian.
pub(super) fn index_of(e: &[u8]) -> u32 {
    match e.len() {
        1 => u32::from(e[0]),
        2 => u32::from(u16::from_le_bytes([e[0], e[1]])),
        _ => u32::from_le_bytes([e[0], e[1], e[2], e[3]]),
    }
}

/// Checks that `count` elements of `size` bytes from byte `offset` of
/// buffer view `view` (at its stride) lie within the view, and the view
/// within its buffer; gives the buffer, the first element's byte in it,
/// and the stride.
fn place(
    view: &gltf::buffer::View<'_>,
    bufs: &Buffers<'_>,
    offset: usize,
    count: usize,
    size: usize,
    what: &str,
) -> Result<(usize, u64, u64), String> {
    let b = view.buffer().index();
    let data = bufs.len(b);
    let view_end = (view.offset() as u64).checked_add(view.length() as u64);
    if view_end.is_none_or(|e| e > data) {
        return Err(format!(
            "buffer view {} ends past its buffer's {data} bytes",
            view.index()
        ));
    }
    let stride = view.stride().unwrap_or(size).max(size);
    let end = match count {
        0 => Some(0),
        n => (n - 1)
            .checked_mul(stride)
            .and_then(|x| x.checked_add(offset))
            .and_then(|x| x.checked_add(size)),
    };
    if end.is_none_or(|e| e > view.length()) {
        return Err(format!(
            "{what} ends past its buffer view's {} bytes",
            view.length()
        ));
    }
    Ok((b, (view.offset() + offset) as u64, stride as u64))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reads through a cache of two pages, out of order, across page
    /// ends: every byte is the file's.
    #[test]
    fn reads_through_a_small_page_cache_are_the_files_bytes() {
        let mut f = tempfile::tempfile().unwrap();
        let bytes: Vec<u8> = (0..5 * PAGE + 123).map(|i| (i * 31 % 251) as u8).collect();
        std::io::Write::write_all(&mut f, &bytes).unwrap();
        let len = bytes.len() as u64 - 7;
        let mut bufs = Buffers {
            data: vec![Data::File {
                file: f,
                start: 7,
                len,
            }],
            pages: Pages::new(2),
            scratch: Vec::new(),
            read: 0,
        };
        let mut at = 0u64;
        for k in 0..400u64 {
            at = (at + 40_009 * k) % len;
            let n = ((k * 977) % 3000).min(len - at) as usize;
            let mut out = vec![0u8; n];
            bufs.read(0, at, &mut out).unwrap();
            assert_eq!(out, bytes[7 + at as usize..][..n], "{n} bytes at {at}");
        }
        assert!(bufs.pages.slots.len() <= 2);
        let mut big = vec![0u8; PAGE + 1];
        bufs.read(0, 3, &mut big).unwrap();
        assert_eq!(big, bytes[10..][..PAGE + 1]);
        assert!(bufs.read(0, len - 2, &mut [0u8; 3]).is_err());
        assert!(bufs.read(1, 0, &mut [0u8; 1]).is_err());
    }

    /// Interleaved elements (a stride past their size), with sparse
    /// replacements, read in chunks and one by one.
    #[test]
    fn strided_and_sparse_elements_read_as_listed() {
        let value = |k: usize| [k as f32, 10.0 + k as f32, -(k as f32)];
        let mut bytes = vec![0xEEu8; 5];
        for k in 0..9 {
            bytes.extend(value(k).iter().flat_map(|c| c.to_le_bytes()));
            bytes.extend([0xAAu8; 8]);
        }
        let mut bufs = Buffers {
            data: vec![Data::Slice(&bytes)],
            pages: Pages::new(2),
            scratch: Vec::new(),
            read: 0,
        };
        let replaced = [7.0f32, 7.5, 8.0];
        let e = Elements {
            index: 0,
            view: Some((0, 5, 20)),
            data_type: DataType::F32,
            dims: Dimensions::Vec3,
            normalized: false,
            size: 12,
            count: 9,
            sparse: Some((
                vec![2, 8],
                replaced
                    .repeat(2)
                    .iter()
                    .flat_map(|c| c.to_le_bytes())
                    .collect(),
            )),
        };
        let want = |k: usize| if k == 2 || k == 8 { replaced } else { value(k) };
        let mut got = Vec::new();
        e.chunks(&mut bufs, |first, raw| {
            assert_eq!(first, got.len());
            got.extend(raw.chunks_exact(12).map(|x| e.decode::<3>(x)));
            Ok(())
        })
        .unwrap();
        assert_eq!(got, (0..9).map(want).collect::<Vec<_>>());
        for k in 0..9 {
            assert_eq!(e.vec3(&mut bufs, k).unwrap(), want(k));
        }
        let mut raw = Vec::new();
        e.raw(&mut bufs, 3, 5, &mut raw).unwrap();
        let part: Vec<[f32; 3]> = raw.chunks_exact(12).map(|x| e.decode::<3>(x)).collect();
        assert_eq!(part, (3..8).map(want).collect::<Vec<_>>());
    }
}
