//! Neutral File Format: a streaming reader and a writer that prints numbers
//! the way the SPD programs do (C's `%g`).

mod gfmt;
mod reader;
mod writer;

pub use gfmt::{fmt_g, round_g6};
pub use reader::{MAX_LINE_BYTES, read_nff, read_nff_from};
pub use writer::NffWriter;
