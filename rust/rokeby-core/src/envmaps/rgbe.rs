//! Radiance RGBE images (`.hdr`, Ward, "Real Pixels", Graphics Gems II, 1991): the other HDR file
//! format environment maps come in (Poly Haven, most HDRI sites), beside OpenEXR.
//!
//! A pixel is three 8-bit mantissas sharing one 8-bit exponent: `m · 2^(e − 136)` per channel, 0
//! when `e = 0` — as Blender reads them (measured: tests/envmaps/test_envmap.py; Radiance's own reader adds
//! ½ to m), so a file reads the same here as in Blender. [`from_float`] rounds to the nearest
//! mantissa (Blender's writer truncates), which keeps the round trip within ½ unit. Files hold an ASCII header
//! (`#?RADIANCE` or `#?RGBE`, `FORMAT=32-bit_rle_rgbe`, a blank line), the resolution line
//! `-Y H +X W` (rows top to bottom) and scanlines, flat or in the "new" run-length encoding
//! (`2 2 W/256 W%256`, then each of the four byte planes as runs: a count above 128 repeats the
//! next byte count − 128 times, else that many literal bytes follow).
//!
//! [`decode`] reads flat and new-RLE files with the standard orientation and refuses the rest with
//! an error naming what it found (XYZE pixels, other orientations, the obsolete old-style RLE);
//! [`encode`] writes new-RLE scanlines. Neither panics on any input (fuzzed by the tests below).

use crate::error::{Result, RokebyError};

fn bad(msg: impl Into<String>) -> RokebyError {
    RokebyError::invalid("data", msg)
}

/// The float colour of one RGBE pixel.
#[inline]
pub fn to_float(p: [u8; 4]) -> [f32; 3] {
    if p[3] == 0 {
        return [0.0; 3];
    }
    let f = pow2(p[3] as i32 - (128 + 8));
    [p[0] as f32 * f, p[1] as f32 * f, p[2] as f32 * f]
}

/// The RGBE pixel of a float colour (negative and non-finite channels are 0; values beyond the
/// format's range, about 1.7e38, saturate).
#[inline]
pub fn from_float(c: [f32; 3]) -> [u8; 4] {
    let c = c.map(|x| {
        if x.is_finite() && x > 0.0 {
            x as f64
        } else {
            0.0
        }
    });
    let v = c[0].max(c[1]).max(c[2]);
    if v < 1e-32 {
        return [0; 4];
    }
    let (mant, exp) = frexp(v); // v = mant · 2^exp, mant in [½, 1)
    if exp + 128 > 255 {
        // beyond the format's largest value: the largest exponent, mantissas in proportion
        let k = 255.0 / v;
        return [(c[0] * k) as u8, (c[1] * k) as u8, (c[2] * k) as u8, 255];
    }
    let d = mant * 256.0 / v; // the largest channel's mantissa is mant · 256 in [128, 256)
    let m = |x: f64| (x * d + 0.5).min(255.0) as u8;
    [m(c[0]), m(c[1]), m(c[2]), (exp + 128) as u8]
}

/// v = m · 2^e with m in [½, 1), for a normal positive finite f64 (the only kind passed here).
fn frexp(v: f64) -> (f64, i32) {
    let e = ((v.to_bits() >> 52) & 0x7ff) as i32 - 1022;
    (v / 2f64.powi(e), e)
}

/// 2^e as f32 (e in −136..=119 here; below f32's normal range it is subnormal, as the value is).
#[inline]
fn pow2(e: i32) -> f32 {
    2f64.powi(e) as f32
}

/// (height, width, RGB float32 pixels, row 0 at the top) of a Radiance file's bytes.
pub fn decode(bytes: &[u8]) -> Result<(usize, usize, Vec<f32>)> {
    let mut pos = 0usize;
    let mut line = || -> Result<String> {
        let start = pos;
        while pos < bytes.len() && bytes[pos] != b'\n' {
            pos += 1;
            if pos - start > 4096 {
                return Err(bad(
                    "header line longer than 4096 bytes: not a Radiance .hdr file",
                ));
            }
        }
        if pos >= bytes.len() {
            return Err(bad("the file ends inside its header"));
        }
        let s = String::from_utf8_lossy(&bytes[start..pos]).into_owned();
        pos += 1;
        Ok(s)
    };
    if !bytes.starts_with(b"#?") {
        let head: String = String::from_utf8_lossy(&bytes[..bytes.len().min(16)])
            .chars()
            .filter(|c| !c.is_control())
            .collect();
        return Err(bad(format!(
            "not a Radiance .hdr file (it starts {head:?}, expected \"#?RADIANCE\")"
        )));
    }
    line()?;
    loop {
        let l = line()?;
        if l.trim().is_empty() {
            break;
        }
        if let Some(f) = l.strip_prefix("FORMAT=") {
            if f.trim() != "32-bit_rle_rgbe" {
                return Err(bad(format!(
                    "pixel format {:?} is not supported (only 32-bit_rle_rgbe)",
                    f.trim()
                )));
            }
        }
    }
    let res = line()?;
    let t: Vec<&str> = res.split_whitespace().collect();
    let (h, w) = match t.as_slice() {
        ["-Y", h, "+X", w] => (h.parse::<usize>().ok(), w.parse::<usize>().ok()),
        _ => {
            return Err(bad(format!(
                "resolution line {res:?}: only the standard orientation \"-Y H +X W\" is supported"
            )))
        }
    };
    let (Some(h), Some(w)) = (h, w) else {
        return Err(bad(format!(
            "resolution line {res:?} does not hold two sizes"
        )));
    };
    if h == 0 || w == 0 || h > 1 << 16 || w > 1 << 16 {
        return Err(bad(format!(
            "image of {w}×{h} pixels: sizes must be 1 to 65536"
        )));
    }
    // Bound what the file can ask for before allocating: every scanline takes at least
    // `min_line` bytes (new RLE: a 4-byte header and at most 127 pixels per 2-byte run in each of
    // the 4 planes; flat: 4 bytes a pixel; old-style RLE is refused below), so a short file that
    // declares a huge image is refused here instead of allocating for it.
    let min_line = if (8..=0x7fff).contains(&w) {
        4 + 8 * w.div_ceil(127)
    } else {
        4 * w
    };
    let have = bytes.len().saturating_sub(pos);
    if (have as u128) < (h as u128) * (min_line as u128) {
        return Err(bad(format!(
            "the file declares {w}×{h} pixels but holds only {have} bytes of pixel data (at least {} needed): it is truncated or not a Radiance .hdr file",
            (h as u128) * (min_line as u128)
        )));
    }
    let mut out = crate::alloc::filled("image", &[h, w, 3], 0.0f32)?;
    let mut row = vec![0u8; 4 * w];
    for y in 0..h {
        let rest = &bytes[pos.min(bytes.len())..];
        let new_rle = (8..=0x7fff).contains(&w)
            && rest.len() >= 4
            && rest[0] == 2
            && rest[1] == 2
            && rest[2] & 0x80 == 0;
        if new_rle {
            let rw = ((rest[2] as usize) << 8) | rest[3] as usize;
            if rw != w {
                return Err(bad(format!(
                    "scanline {y} says it is {rw} pixels wide, the image is {w}"
                )));
            }
            pos += 4;
            for plane in 0..4 {
                let mut x = 0;
                while x < w {
                    let Some(&count) = bytes.get(pos) else {
                        return Err(bad(format!("the file ends in scanline {y}")));
                    };
                    pos += 1;
                    if count > 128 {
                        let n = (count - 128) as usize;
                        let Some(&v) = bytes.get(pos) else {
                            return Err(bad(format!("the file ends in scanline {y}")));
                        };
                        pos += 1;
                        if n > w - x {
                            return Err(bad(format!(
                                "scanline {y}: a run goes past the image's width"
                            )));
                        }
                        for k in 0..n {
                            row[4 * (x + k) + plane] = v;
                        }
                        x += n;
                    } else {
                        let n = count as usize;
                        if n == 0 || n > w - x {
                            return Err(bad(format!(
                                "scanline {y}: a literal run of {n} bytes does not fit the width"
                            )));
                        }
                        let Some(lit) = bytes.get(pos..pos + n) else {
                            return Err(bad(format!("the file ends in scanline {y}")));
                        };
                        for (k, &v) in lit.iter().enumerate() {
                            row[4 * (x + k) + plane] = v;
                        }
                        pos += n;
                        x += n;
                    }
                }
            }
        } else {
            let Some(flat) = bytes.get(pos..pos + 4 * w) else {
                return Err(bad(format!("the file ends in scanline {y}")));
            };
            if flat
                .chunks_exact(4)
                .any(|p| p[0] == 1 && p[1] == 1 && p[2] == 1)
            {
                return Err(bad("old-style run-length encoding (1 1 1 n pixels) is not supported: re-save the file (e.g. from Blender)"));
            }
            row.copy_from_slice(flat);
            pos += 4 * w;
        }
        for (x, p) in row.chunks_exact(4).enumerate() {
            let c = to_float([p[0], p[1], p[2], p[3]]);
            out[3 * (y * w + x)..3 * (y * w + x) + 3].copy_from_slice(&c);
        }
    }
    Ok((h, w, out))
}

/// The bytes of a Radiance file of an (h, w) RGB float image (row 0 at the top), new-RLE
/// scanlines (flat ones where the width is outside 8..=32767, as the format requires).
pub fn encode(h: usize, w: usize, rgb: &[f32]) -> Result<Vec<u8>> {
    if h == 0 || w == 0 || h > 1 << 16 || w > 1 << 16 {
        return Err(RokebyError::invalid(
            "pixels",
            format!("image of {w}×{h} pixels: sizes must be 1 to 65536"),
        ));
    }
    if rgb.len() != h * w * 3 {
        return Err(RokebyError::invalid(
            "pixels",
            format!(
                "expected {} values for {w}×{h} RGB, got {}",
                h * w * 3,
                rgb.len()
            ),
        ));
    }
    let mut out =
        format!("#?RADIANCE\n# Made with Rokeby\nFORMAT=32-bit_rle_rgbe\n\n-Y {h} +X {w}\n")
            .into_bytes();
    out.reserve(h * w * 4);
    let mut plane = vec![0u8; w];
    for y in 0..h {
        let px: Vec<[u8; 4]> = (0..w)
            .map(|x| {
                from_float([
                    rgb[3 * (y * w + x)],
                    rgb[3 * (y * w + x) + 1],
                    rgb[3 * (y * w + x) + 2],
                ])
            })
            .collect();
        if !(8..=0x7fff).contains(&w) {
            out.extend(px.iter().flatten());
            continue;
        }
        out.extend_from_slice(&[2, 2, (w >> 8) as u8, (w & 0xff) as u8]);
        for c in 0..4 {
            for (x, p) in px.iter().enumerate() {
                plane[x] = p[c];
            }
            rle_plane(&plane, &mut out);
        }
    }
    Ok(out)
}

/// One byte plane as runs (≥ 4 equal bytes, up to 127) and literals (up to 128).
fn rle_plane(p: &[u8], out: &mut Vec<u8>) {
    let mut x = 0;
    while x < p.len() {
        // the next run of at least 4 equal bytes
        let mut run_start = x;
        let mut run_len = 0;
        while run_start < p.len() {
            run_len = 1;
            while run_start + run_len < p.len()
                && run_len < 127
                && p[run_start + run_len] == p[run_start]
            {
                run_len += 1;
            }
            if run_len >= 4 {
                break;
            }
            run_start += run_len;
        }
        if run_start >= p.len() {
            run_len = 0;
        }
        // literals up to the run
        while x < run_start {
            let n = (run_start - x).min(128);
            out.push(n as u8);
            out.extend_from_slice(&p[x..x + n]);
            x += n;
        }
        if run_len >= 4 {
            out.push(128 + run_len as u8);
            out.push(p[run_start]);
            x = run_start + run_len;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rng(seed: &mut u64) -> f64 {
        *seed ^= *seed << 13;
        *seed ^= *seed >> 7;
        *seed ^= *seed << 17;
        (*seed >> 11) as f64 / (1u64 << 53) as f64
    }

    #[test]
    fn round_trip_within_the_formats_precision() {
        let mut s = 0x9e3779b97f4a7c15u64;
        for &(h, w) in &[(1usize, 1usize), (3, 7), (5, 8), (4, 300), (2, 40000)] {
            let mut px = vec![0.0f32; h * w * 3];
            for (i, v) in px.iter_mut().enumerate() {
                // constant stretches (runs), noise (literals), zeros, a huge and a tiny range
                *v = match (i / 3 / 17) % 4 {
                    0 => 0.25,
                    1 => (rng(&mut s) * 4.0) as f32,
                    2 => 0.0,
                    _ => (10f64.powf(rng(&mut s) * 60.0 - 30.0)) as f32,
                };
            }
            let bytes = encode(h, w, &px).unwrap();
            let (h2, w2, back) = decode(&bytes).unwrap();
            assert_eq!((h2, w2), (h, w));
            for p in 0..h * w {
                let m = (0..3).map(|c| px[3 * p + c]).fold(0.0f32, f32::max);
                for c in 0..3 {
                    // one shared exponent, rounded mantissas: within ½ unit ≤ 1/256 of the pixel's largest
                    assert!(
                        (back[3 * p + c] - px[3 * p + c]).abs() <= m / 256.0 * 1.0001 + 1e-38,
                        "{h}x{w} pixel {p}: {} vs {}",
                        back[3 * p + c],
                        px[3 * p + c]
                    );
                }
            }
        }
    }

    #[test]
    fn runs_compress_a_constant_image() {
        let px = vec![0.5f32; 64 * 256 * 3];
        let bytes = encode(64, 256, &px).unwrap();
        assert!(bytes.len() < 64 * 256 * 4 / 20, "{} bytes", bytes.len()); // runs of 127: ~8 bytes per plane and row
        let (_, _, back) = decode(&bytes).unwrap();
        assert!(back.iter().all(|&v| (v - 0.5).abs() < 0.5 / 128.0));
    }

    #[test]
    fn flat_scanlines_and_known_pixels() {
        // (128, 64, 32, e=129): m·2^(129−136)
        let mut f = b"#?RGBE\n\n-Y 1 +X 2\n".to_vec();
        f.extend_from_slice(&[128, 64, 32, 129, 0, 0, 0, 0]);
        let (h, w, px) = decode(&f).unwrap();
        assert_eq!((h, w), (1, 2));
        assert_eq!(&px[..3], &[1.0, 0.5, 0.25]);
        assert_eq!(&px[3..], &[0.0, 0.0, 0.0]);
        assert_eq!(from_float([1.0, 0.5, 0.25]), [128, 64, 32, 129]);
        assert_eq!(from_float([f32::NAN, -1.0, 0.0]), [0, 0, 0, 0]);
    }

    #[test]
    fn bad_files_are_errors_not_panics() {
        let good = encode(3, 20, &vec![0.3f32; 3 * 20 * 3]).unwrap();
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (b"P6\n3 3\n255\n".to_vec(), "not a Radiance"),
            (
                b"#?RADIANCE\nFORMAT=32-bit_rle_xyze\n\n-Y 1 +X 1\n\0\0\0\0".to_vec(),
                "xyze",
            ),
            (b"#?RADIANCE\n\n+Y 1 +X 1\n\0\0\0\0".to_vec(), "orientation"),
            (b"#?RADIANCE\n\n-Y 0 +X 1\n".to_vec(), "sizes"),
            (
                b"#?RADIANCE\n\n-Y 1 +X 2\n\x01\x01\x01\x05\0\0\0\0".to_vec(),
                "old-style",
            ),
            (good[..good.len() - 5].to_vec(), "truncated"),
            // 53 bytes declaring 65536×65536 (allocated 51.5 GB and aborted)
            (
                b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 65536 +X 65536\n\x02\x02\x01\x00"
                    .to_vec(),
                "declares 65536×65536",
            ),
            (
                b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe".to_vec(),
                "ends inside its header",
            ),
        ];
        for (bytes, want) in cases {
            let e = decode(&bytes).unwrap_err().to_string();
            assert!(e.contains(want), "{e:?} should say {want:?}");
        }
        // every truncation and every single-byte corruption of a real file: an error or an image, never a panic
        for n in 0..good.len() {
            let _ = decode(&good[..n]);
            let mut c = good.clone();
            c[n] ^= 0xa5;
            let _ = decode(&c);
        }
        assert!(encode(2, 2, &[0.0; 5]).is_err());
    }
}
