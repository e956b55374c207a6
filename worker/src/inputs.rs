//! A task's input records: received from the coordinator, or named by it
//! among those this worker keeps ([`crate::kept`]). Received records are
//! gathered in memory while the share lasts, else in spill files.

use crate::exec::Input;
use crate::kept::{KeptStore, ResultSlice, Slice};
use sray_engine::bf::{Outcome, RayRec, ResultRec, Tracer};
use sray_engine::simd::Elem;
use sray_engine::spill::{MemoryShare, RecordsWriter, SpillDir};
use sray_proto::v1::RecordKind;
use sray_proto::wire::{decode_chunk, records_per_chunk};

/// A task's input records, kept here or received.
#[derive(Default)]
pub struct Inputs {
    pub rays: Option<Slice<RayRec>>,
    pub results: Option<ResultSlice>,
}

/// Where a task's input of one kind is gathered: nothing yet, one kept
/// slice as it is, or records copied into records of their own (in
/// memory while the share lasts).
enum Gather<T: bytemuck::Pod> {
    Empty,
    Slice(Slice<T>),
    Copy(RecordsWriter<T>),
}

impl<T: bytemuck::Pod> Gather<T> {
    fn copy(
        &mut self,
        share: &MemoryShare,
        spill: &SpillDir,
        what: &'static str,
    ) -> Result<&mut RecordsWriter<T>, String> {
        let io = |e: sray_engine::Error| e.to_string();
        match std::mem::replace(self, Gather::Empty) {
            Gather::Empty => *self = Gather::Copy(RecordsWriter::new(share, spill, what)),
            Gather::Slice(s) => {
                let mut w = RecordsWriter::new(share, spill, what);
                copy_into(&s, &mut w, |r| r).map_err(io)?;
                *self = Gather::Copy(w);
            }
            c @ Gather::Copy(_) => *self = c,
        }
        match self {
            Gather::Copy(w) => Ok(w),
            _ => unreachable!("made a copy"),
        }
    }

    fn add(
        &mut self,
        share: &MemoryShare,
        spill: &SpillDir,
        what: &'static str,
        recs: &[T],
    ) -> Result<(), String> {
        self.copy(share, spill, what)?
            .extend(recs)
            .map_err(|e| e.to_string())
    }

    fn add_kept(
        &mut self,
        share: &MemoryShare,
        spill: &SpillDir,
        what: &'static str,
        s: Slice<T>,
    ) -> Result<(), String> {
        if let Gather::Empty = self {
            *self = Gather::Slice(s);
            return Ok(());
        }
        let w = self.copy(share, spill, what)?;
        copy_into(&s, w, |r| r).map_err(|e| e.to_string())
    }

    fn finish(self) -> Result<Option<Slice<T>>, String> {
        Ok(match self {
            Gather::Empty => None,
            Gather::Slice(s) => Some(s),
            Gather::Copy(w) => Some(Slice::whole(w.finish().map_err(|e| e.to_string())?)),
        })
    }
}

/// Appends a slice's records, mapped by `f`, to `w`.
fn copy_into<S: bytemuck::Pod, T: bytemuck::Pod>(
    s: &Slice<S>,
    w: &mut RecordsWriter<T>,
    f: impl Fn(S) -> T,
) -> Result<(), sray_engine::Error> {
    let mut rd = s.reader()?;
    let (mut src, mut buf) = (Vec::with_capacity(4096), Vec::with_capacity(4096));
    while rd.next_chunk(&mut src, 4096)? {
        buf.clear();
        buf.extend(src.iter().map(|&r| f(r)));
        w.extend(&buf)?;
    }
    Ok(())
}

/// A task's results as they are gathered: the kept results with their
/// surfaces, if that is all the input holds, else bare results.
enum GatherResults {
    Carried(Slice<Outcome>),
    Bare(Gather<ResultRec>),
}

impl GatherResults {
    /// Goes over to bare results (keeping what came so far, in order).
    fn bare(
        &mut self,
        share: &MemoryShare,
        spill: &SpillDir,
    ) -> Result<&mut Gather<ResultRec>, String> {
        if let GatherResults::Carried(s) = self {
            let mut w = RecordsWriter::new(share, spill, "in-results");
            copy_into(s, &mut w, |o| o.res).map_err(|e| e.to_string())?;
            *self = GatherResults::Bare(Gather::Copy(w));
        }
        match self {
            GatherResults::Bare(g) => Ok(g),
            GatherResults::Carried(_) => unreachable!("made bare"),
        }
    }

    fn is_empty(&self) -> bool {
        matches!(self, GatherResults::Bare(Gather::Empty))
    }

    fn finish(self) -> Result<Option<ResultSlice>, String> {
        Ok(match self {
            GatherResults::Carried(s) => Some(ResultSlice::Carried(s)),
            GatherResults::Bare(g) => g.finish()?.map(ResultSlice::Bare),
        })
    }
}

pub(crate) fn read_inputs<R: Elem>(
    tracer: &Tracer<R>,
    rt: &tokio::runtime::Handle,
    kept: &mut KeptStore,
    share: &MemoryShare,
    input: Input,
) -> Result<Inputs, String> {
    let mut inputs = Inputs::default();
    let (mut stream, mut chunks) = match input {
        Input::None => return Ok(inputs),
        Input::Files(f) => return Ok(f),
        Input::Stream(s) => (Some(s), Vec::new().into_iter()),
        Input::Chunks(c) => (None, c.into_iter()),
    };
    let mut rays = Gather::<RayRec>::Empty;
    let mut results = GatherResults::Bare(Gather::Empty);
    let spill = &tracer.spill;
    loop {
        let msg = match &mut stream {
            Some(s) => rt
                .block_on(s.message())
                .map_err(|s| format!("task input: {}", s.message()))?,
            None => chunks.next(),
        };
        let Some(chunk) = msg else { break };
        let kind = RecordKind::try_from(chunk.kind);
        if let Some(h) = &chunk.held {
            let k = kept.by_task.get(&h.task_id).ok_or_else(|| {
                format!(
                    "task input: the records of task {} are not kept here",
                    h.task_id
                )
            })?;
            let gone = || {
                format!(
                    "task input: no records {}+{} of task {} here",
                    h.offset, h.count, h.task_id
                )
            };
            match kind {
                Ok(RecordKind::Rays) => {
                    let s = k
                        .rays
                        .as_ref()
                        .and_then(|s| s.sub(h.offset, h.count))
                        .ok_or_else(gone)?;
                    rays.add_kept(share, spill, "in-rays", s)?;
                }
                Ok(RecordKind::Results) => {
                    // A shading named an intersection's whole results
                    // with their surfaces takes them (and drops the
                    // intersection's entry, whose rays came first): no
                    // task asks for them again, a retry gets them from the
                    // coordinator, and the tracer shades from their buffer
                    // as it is (see `result_reader`).
                    let whole = results.is_empty()
                        && h.offset == 0
                        && matches!(&k.results, Some(ResultSlice::Carried(c)) if c.len() == h.count);
                    let s = if whole {
                        kept.remove(h.task_id).and_then(|k| k.results)
                    } else {
                        k.results.as_ref().and_then(|s| s.sub(h.offset, h.count))
                    }
                    .ok_or_else(gone)?;
                    match s {
                        ResultSlice::Carried(c) if results.is_empty() => {
                            results = GatherResults::Carried(c);
                        }
                        ResultSlice::Carried(c) => {
                            let g = results.bare(share, spill)?;
                            let w = g.copy(share, spill, "in-results")?;
                            copy_into(&c, w, |o| o.res).map_err(|e| e.to_string())?;
                        }
                        ResultSlice::Bare(b) => {
                            results
                                .bare(share, spill)?
                                .add_kept(share, spill, "in-results", b)?;
                        }
                    }
                }
                _ => return Err(format!("task input: unexpected record kind {}", chunk.kind)),
            }
            continue;
        }
        match kind {
            Ok(RecordKind::Rays) => {
                let v =
                    decode_chunk::<RayRec>(&chunk.data, chunk.raw, records_per_chunk::<RayRec>())
                        .map_err(|e| e.to_string())?;
                rays.add(share, spill, "in-rays", &v)?
            }
            Ok(RecordKind::Results) => {
                let v = decode_chunk::<ResultRec>(
                    &chunk.data,
                    chunk.raw,
                    records_per_chunk::<ResultRec>(),
                )
                .map_err(|e| e.to_string())?;
                results
                    .bare(share, spill)?
                    .add(share, spill, "in-results", &v)?
            }
            _ => return Err(format!("task input: unexpected record kind {}", chunk.kind)),
        }
    }
    inputs.rays = rays.finish()?;
    inputs.results = results.finish()?;
    Ok(inputs)
}
