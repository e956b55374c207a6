//! Compiles sray.proto with protox, a protobuf compiler written in Rust, so
//! that building needs no system `protoc`.

fn main() -> Result<(), Box<dyn std::error::Error>> {
    println!("cargo:rerun-if-changed=sray.proto");
    let descriptors = protox::compile(["sray.proto"], ["."])?;
    tonic_prost_build::configure().compile_fds(descriptors)?;
    Ok(())
}
