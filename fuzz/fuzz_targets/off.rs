//! The OFF reader on arbitrary bytes: it must stream a mesh into the sink
//! or return an error naming the file and where, never panic, never
//! allocate by a count in the file beyond what the file holds, and every
//! object it emits must be valid and safe to intersect.
#![no_main]

mod common;

use libfuzzer_sys::fuzz_target;
use sray_engine::input::Wrapping;
use std::path::Path;

fuzz_target!(|data: &[u8]| {
    let opts = common::options(data);
    let _ = sray_engine::mesh::off::read_off_from(data, Wrapping::Plain, Path::new("fuzz.off"), &mut common::Sink, &common::Quiet, &opts);
});
