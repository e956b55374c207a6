//! Texture images on arbitrary bytes: decoding must end in a texture or
//! an error naming the image (KTX2 and formats other than PNG and JPEG
//! refused by name), never a panic; sampling a decoded texture with every
//! wrap mode and filter, at any coordinates (huge, negative, not finite),
//! must stay inside the image.
#![no_main]

use libfuzzer_sys::fuzz_target;
use sray_engine::texture::{Encoding, Filter, Sampler, Texture, UvTransform, Wrap};

fuzz_target!(|data: &[u8]| {
    let Ok(t) = Texture::decode(data, "fuzz image", Encoding::Srgb) else {
        return;
    };
    let uvs = [
        [0.0, 0.0],
        [0.5, 0.5],
        [1.0, 1.0],
        [-3.7, 12.25],
        [1e30, -1e30],
        [f32::NAN, 0.5],
        [f32::INFINITY, f32::NEG_INFINITY],
    ];
    let transform = UvTransform {
        offset: [0.25, -0.5],
        rotation: 1.0,
        scale: [3.0, -2.0],
    };
    for wrap in [Wrap::Repeat, Wrap::ClampToEdge, Wrap::MirroredRepeat] {
        for filter in [Filter::Nearest, Filter::Linear] {
            let s = Sampler {
                wrap_s: wrap,
                wrap_t: wrap,
                filter,
            };
            for uv in uvs {
                let _ = t.sample(&s, uv);
                let _ = t.sample(&s, transform.apply(uv));
            }
        }
    }
});
