//! rgbe: Radiance .hdr decoding of arbitrary bytes, raw and behind a valid header (so
//! the scanline decoder sees the adversarial part), and encode → decode of what decoded. Never a
//! panic; decoded pixels are finite and non-negative; a re-encoded image decodes to the same size
//! and each channel within ½ mantissa unit of its pixel's largest.
#![no_main]
use libfuzzer_sys::fuzz_target;
use rokeby_core::envmaps::rgbe::{decode, encode};

fuzz_target!(|data: &[u8]| {
    let w = 1 + data.first().copied().unwrap_or(0) as usize % 40;
    let mut framed = format!("#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 3 +X {w}\n").into_bytes();
    framed.extend_from_slice(data.get(1..).unwrap_or(&[]));
    for bytes in [data, &framed[..]] {
        if let Ok((h, w, px)) = decode(bytes) {
            assert_eq!(px.len(), h * w * 3);
            assert!(px.iter().all(|x| x.is_finite() && *x >= 0.0));
            let again = encode(h, w, &px).expect("a decoded image encodes");
            let (h2, w2, back) = decode(&again).expect("an encoded image decodes");
            assert_eq!((h2, w2), (h, w));
            for (p, q) in px.chunks_exact(3).zip(back.chunks_exact(3)) {
                let m = p.iter().fold(0.0f32, |a, &b| a.max(b));
                for c in 0..3 {
                    assert!((p[c] - q[c]).abs() <= m / 256.0 * 1.0001 + 1e-37, "{p:?} -> {q:?}");
                }
            }
        }
    }
});
