//! exr_io: OpenEXR decoding of arbitrary bytes, raw and after the bytes of a small valid file
//! written here (so the header parser and the chunk decoders see the adversarial part), with and
//! without DWA. Never a panic; every channel covers its part's data window.
#![no_main]
use libfuzzer_sys::fuzz_target;
use rokeby_core::exr_io::{compression_from_name, read, write, Samples, WriteChannel};

fuzz_target!(|data: &[u8]| {
    let r: Vec<f32> = (0..12).map(|i| i as f32 * 0.5).collect();
    let good = write(
        4,
        3,
        &[WriteChannel { name: "R", samples: &r, half: false }],
        &[],
        compression_from_name("zip").expect("zip"),
    )
    .expect("a small file writes");
    let cut = data.first().copied().unwrap_or(0) as usize % good.len();
    let mut spliced = good[..cut].to_vec();
    spliced.extend_from_slice(data.get(1..).unwrap_or(&[]));
    for bytes in [data, &spliced[..]] {
        for dwa in [false, true] {
            let Ok(parts) = read(bytes, dwa) else { continue };
            for p in parts {
                for c in &p.channels {
                    let n = match &c.samples {
                        Samples::F32(v) => v.len(),
                        Samples::U32(v) => v.len(),
                    };
                    assert_eq!(n, p.width * p.height);
                }
            }
        }
    }
});
