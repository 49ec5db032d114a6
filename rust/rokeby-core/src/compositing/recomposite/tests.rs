use super::*;

/// A per-pixel implementation of eqs. 3–5, the reference of these tests: one pixel at a
/// time, scalar, f64 normalisation of n, ñ and v (as [`unit_row`]) and f32 arithmetic after it.
fn recomposite_scalar(b: &Buffers, patches: &[Patch], p: &Params) -> Result<(Vec<f32>, Stats)> {
    validate(b, patches, p)?;
    // Per-patch constants, once per frame: f32 SH coefficients (channel-major) and flags.
    let sh32: Vec<Option<[[f32; SH_COEFFS]; 3]>> = patches
        .iter()
        .map(|q| q.sh.map(|c| c.map(|ch| ch.map(|x| x as f32))))
        .collect();
    let (k_d, k_r) = (p.k_d as f32, p.k_r as f32);
    let unit_material = p.k_d == 1.0 && p.k_r == 1.0;
    let inv_gamma = (1.0 / p.gamma) as f32;
    let gamma_one = p.gamma == 1.0;
    let inv_eps = (1.0 / p.epsilon) as f32;
    let chord_eps = if p.epsilon >= std::f64::consts::PI {
        f32::INFINITY
    } else {
        (2.0 * (0.5 * p.epsilon).sin()) as f32
    };
    let const_view = if b.view.len() == 3 {
        unit_row(b.view).map(to32)
    } else {
        None
    };
    let g = |x: f32| {
        if gamma_one {
            x
        } else {
            x.max(0.0).powf(inv_gamma)
        }
    };
    // Rows in parallel; every pixel starts as I (one copy), and only pixels whose normal or
    // material changed run eqs. 3–5 — in f32 (the buffers' precision): with ñ = n the formulas
    // below still give I bit for bit (zero SH difference, zero chord, identical shade and shade0).
    let mut out = b.image.to_vec();
    const CHUNK: usize = 1024;
    let stats = out
        .par_chunks_mut(3 * CHUNK)
        .enumerate()
        .map(|(chunk, o)| {
            let mut st = Stats::default();
            for (k, px) in o.chunks_exact_mut(3).enumerate() {
                let i = chunk * CHUNK + k;
                let id = b.ids[i];
                if id < 0 || id as usize >= patches.len() {
                    continue;
                }
                let nb = &b.normals[3 * i..3 * i + 3];
                let eb = &b.edited[3 * i..3 * i + 3];
                if unit_material && nb == eb {
                    // Unmodified normal and material: eqs. 3–5 give I exactly; skip the arithmetic.
                    continue;
                }
                let patch = &patches[id as usize];
                let sh = &sh32[id as usize];
                if sh.is_none() && patch.env.is_none() {
                    st.masked += 1;
                    continue;
                }
                let opt = |v: &[f32]| if v.is_empty() { 1.0 } else { v[i] };
                let col = |v: &[f32]| -> [f32; 3] {
                    if v.is_empty() {
                        [1.0; 3]
                    } else {
                        [v[3 * i], v[3 * i + 1], v[3 * i + 2]]
                    }
                };
                let d0 = [b.diffuse[3 * i], b.diffuse[3 * i + 1], b.diffuse[3 * i + 2]];
                let r0 = [
                    b.reflection[3 * i],
                    b.reflection[3 * i + 1],
                    b.reflection[3 * i + 2],
                ];
                let (ad, ar, a) = (opt(b.alpha_d), opt(b.alpha_r), opt(b.alpha));
                let (cd, cr) = (col(b.diffuse_color), col(b.reflection_color));
                let finite = d0
                    .iter()
                    .chain(&r0)
                    .chain(&cd)
                    .chain(&cr)
                    .all(|x| x.is_finite())
                    && ad.is_finite()
                    && ar.is_finite()
                    && a.is_finite();
                let vv = match const_view {
                    Some(v) => Some(v),
                    None if b.view.len() == 3 => None,
                    None => unit_row(&b.view[3 * i..3 * i + 3]).map(to32),
                };
                let (Some(nn), Some(ne), Some(vv)) =
                    (unit_row(nb).map(to32), unit_row(eb).map(to32), vv)
                else {
                    st.masked += 1;
                    continue;
                };
                if !finite {
                    st.masked += 1;
                    continue;
                }
                st.edited += 1;
                // Eq. 3: D(ñ) − D(n) = Σ_k c_k (Y_k(ñ) − Y_k(n)), the basis evaluated once per normal.
                let mut dt = [0.0f32; 3];
                let dbasis = if sh.is_some() {
                    let (be, bn) = (basis32(ne), basis32(nn));
                    std::array::from_fn(|k| be[k] - bn[k])
                } else {
                    [0.0f32; SH_COEFFS]
                };
                for c in 0..3 {
                    let delta = match sh {
                        Some(co) => {
                            let mut s = 0.0f32;
                            for k in 0..SH_COEFFS {
                                s += co[c][k] * dbasis[k];
                            }
                            s
                        }
                        None => 0.0,
                    };
                    let res = (d0[c] + delta).max(d0[c].min(0.0));
                    dt[c] = d0[c] + ad * (res - d0[c]);
                }
                // Eq. 4. The angle from the chord |r − r~| = 2 sin(θ/2): v = 1 without any
                // trigonometry once the chord reaches 2 sin(ε/2); exactly 0 when r~ = r.
                let r = reflect32(vv, nn);
                let re = reflect32(vv, ne);
                let dr = [r[0] - re[0], r[1] - re[1], r[2] - re[2]];
                let chord = (dr[0] * dr[0] + dr[1] * dr[1] + dr[2] * dr[2]).sqrt();
                let vis = if chord >= chord_eps {
                    1.0
                } else {
                    2.0 * (0.5 * chord).min(1.0).asin() * inv_eps
                };
                let look = match &patch.env {
                    Some(env) if vis * ar != 0.0 => lookup32(env, re),
                    _ => r0,
                };
                // Eqs. 4 and 5.
                for c in 0..3 {
                    let rt = r0[c] + vis * ar * (look[c] - r0[c]);
                    let shade = k_d * (cd[c] * dt[c]) + k_r * (cr[c] * rt);
                    let shade0 = cd[c] * d0[c] + cr[c] * r0[c];
                    px[c] += a * (g(shade) - g(shade0));
                }
            }
            st
        })
        .reduce(Stats::default, add);
    Ok((out, stats))
}

#[inline]
fn reflect32(v: [f32; 3], n: [f32; 3]) -> [f32; 3] {
    let d = 2.0 * (n[0] * v[0] + n[1] * v[1] + n[2] * v[2]);
    [d * n[0] - v[0], d * n[1] - v[1], d * n[2] - v[2]]
}

/// [`sh::basis`] in f32.
#[inline]
fn basis32(n: [f32; 3]) -> [f32; SH_COEFFS] {
    let [x, y, z] = n;
    let (c0, c1, c2) = (0.282_094_8_f32, 0.488_602_5_f32, 1.092_548_4_f32);
    [
        c0,
        c1 * y,
        c1 * z,
        c1 * x,
        c2 * x * y,
        c2 * y * z,
        0.315_391_57 * (3.0 * z * z - 1.0),
        c2 * x * z,
        0.546_274_2 * (x * x - y * y),
    ]
}

/// `ParaboloidMap::lookup` for 3 channels in f32: the same face choice, texel convention (texel
/// centres, coordinates clamped to the map) and bilinear weights.
#[inline]
fn lookup32(m: &ParaboloidMap, d: [f32; 3]) -> [f32; 3] {
    let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    let d = if l > 0.0 && l.is_finite() {
        [d[0] / l, d[1] / l, d[2] / l]
    } else {
        [0.0, 0.0, 1.0]
    };
    let face = usize::from(d[2] < 0.0);
    let k = 1.0 / (1.0 + d[2].abs());
    let s = m.size as f32;
    let x = ((d[0] * k + 1.0) * 0.5 * s - 0.5).clamp(0.0, s - 1.0);
    let y = ((d[1] * k + 1.0) * 0.5 * s - 0.5).clamp(0.0, s - 1.0);
    let (j0, i0) = (x as usize, y as usize);
    let (j1, i1) = ((j0 + 1).min(m.size - 1), (i0 + 1).min(m.size - 1));
    let (fx, fy) = (x - j0 as f32, y - i0 as f32);
    let idx = |i: usize, j: usize| ((face * m.size + i) * m.size + j) * 3;
    let (k00, k01, k10, k11) = (idx(i0, j0), idx(i0, j1), idx(i1, j0), idx(i1, j1));
    let t = &m.data;
    std::array::from_fn(|c| {
        let top = t[k00 + c] + fx * (t[k01 + c] - t[k00 + c]);
        let bot = t[k10 + c] + fx * (t[k11 + c] - t[k10 + c]);
        top + fy * (bot - top)
    })
}

/// A small deterministic generator (xorshift64*), uniform in [0, 1).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        ((self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 40) as f32) / (1u64 << 24) as f32
    }
}

/// The batched path (AVX2 where detected, and the portable one) against the per-pixel scalar
/// reference on a random frame: patches with SH + map, SH only, map only, nothing and ids
/// beyond the list; unmodified, slightly and strongly edited normals (v from asin and v = 1);
/// zero and non-finite normals, NaN/inf shading and α; a pixel count that is not a multiple
/// of 8 (nor are the edited pixels of a chunk); γ = 1 and 2.2; k_D, k_R = 1 and not; per-pixel
/// and constant views; tiny, huge and nearly-too-short normals (classified as [`unit_row`] does).
/// The same edited/masked counts, values within 2e-5·(1 + |I~|) of the reference (the batched
/// path normalises with a Newton-refined f32 estimate and raises to 1/γ by polynomials, not
/// `powf`), and the same bits from the portable and the AVX2 paths.
#[test]
fn recomposite_batches_match_scalar_reference() {
    let mut g = Rng(0x9e37_79b9_7f4a_7c15);
    let (w, h) = (97, 43); // 4171 pixels: 4 chunks, the last one partial
    let n = w * h;
    let map = |g: &mut Rng, size: usize| ParaboloidMap {
        size,
        channels: 3,
        data: (0..2 * size * size * 3).map(|_| g.next()).collect(),
    };
    let sh = |g: &mut Rng| -> [[f64; SH_COEFFS]; 3] {
        std::array::from_fn(|_| std::array::from_fn(|_| 2.0 * g.next() as f64 - 1.0))
    };
    let patches = vec![
        Patch {
            sh: Some(sh(&mut g)),
            env: Some(map(&mut g, 16)),
        },
        Patch {
            sh: Some(sh(&mut g)),
            env: None,
        },
        Patch {
            sh: None,
            env: Some(map(&mut g, 5)),
        },
        Patch {
            sh: None,
            env: None,
        },
        Patch {
            sh: Some(sh(&mut g)),
            env: Some(map(&mut g, 1)),
        },
    ];
    let mut ids = vec![0i32; n];
    let mut normals = vec![0.0f32; 3 * n];
    let mut edited = vec![0.0f32; 3 * n];
    let mut view = vec![0.0f32; 3 * n];
    let buf = |g: &mut Rng, lo: f32, hi: f32| -> Vec<f32> {
        (0..3 * n).map(|_| lo + (hi - lo) * g.next()).collect()
    };
    let mut diffuse = buf(&mut g, -0.1, 2.0);
    let reflection = buf(&mut g, 0.0, 2.0);
    let image = buf(&mut g, 0.0, 3.0);
    let dcol = buf(&mut g, 0.0, 1.0);
    let rcol = buf(&mut g, 0.0, 1.0);
    let mut alpha_d: Vec<f32> = (0..n).map(|_| g.next()).collect();
    let alpha_r: Vec<f32> = (0..n).map(|_| g.next()).collect();
    let alpha: Vec<f32> = (0..n).map(|_| g.next()).collect();
    for i in 0..n {
        // Runs of one patch (uniform batches) and mixed stretches.
        ids[i] = if (i / 200) % 3 == 2 {
            (g.next() * 7.0) as i32 - 1
        } else {
            ((i / 200) % 5) as i32
        };
        let nv = [2.0 * g.next() - 1.0, 2.0 * g.next() - 1.0, 0.2 + g.next()];
        normals[3 * i..3 * i + 3].copy_from_slice(&nv);
        let kind = g.next();
        let e = if kind < 0.25 {
            nv
        } else if kind < 0.4 {
            [nv[0] + 1e-3 * g.next(), nv[1], nv[2]]
        } else if kind < 0.45 {
            [2.0 * nv[0], 2.0 * nv[1], 2.0 * nv[2]]
        } else {
            [
                nv[0] + g.next() - 0.5,
                nv[1] - 0.3,
                nv[2] * (0.2 + g.next()),
            ]
        };
        edited[3 * i..3 * i + 3].copy_from_slice(&e);
        let vv = [0.3 * (g.next() - 0.5), 0.3 * (g.next() - 0.5), 1.0];
        view[3 * i..3 * i + 3].copy_from_slice(&vv);
    }
    // Non-finite and degenerate inputs.
    for &(i, what) in &[
        (5usize, 0),
        (300, 1),
        (301, 2),
        (777, 3),
        (1500, 4),
        (2222, 5),
        (4170, 0),
        (3001, 6),
        (2500, 7),
        (2501, 8),
        (2502, 9),
        (2503, 10),
        (2504, 11),
    ] {
        match what {
            // Beyond f32 squares (the f64 fallback): accepted.
            7 => edited[3 * i..3 * i + 3].copy_from_slice(&[3e20, -1e20, 2e19]),
            8 => view[3 * i..3 * i + 3].copy_from_slice(&[0.0, 2e-20, 1e-20]),
            // Around unit_row()'s 1e-12 limit: 9.9999998e-13 (as f32) is too short, 2e-12 not.
            9 => normals[3 * i..3 * i + 3].copy_from_slice(&[1e-12, 0.0, 0.0]),
            10 => edited[3 * i..3 * i + 3].copy_from_slice(&[0.0, -2e-12, 0.0]),
            11 => edited[3 * i..3 * i + 3].copy_from_slice(&[f32::INFINITY, 0.0, 1.0]),
            0 => edited[3 * i] = f32::NAN,
            1 => normals[3 * i..3 * i + 3].copy_from_slice(&[0.0; 3]),
            2 => diffuse[3 * i + 1] = f32::INFINITY,
            3 => alpha_d[i] = f32::NAN,
            4 => view[3 * i..3 * i + 3].copy_from_slice(&[0.0; 3]),
            5 => edited[3 * i..3 * i + 3].copy_from_slice(&[1e-30; 3]),
            _ => diffuse[3 * i] = f32::NAN,
        }
    }
    let mut cases = 0;
    let mut worst = 0.0f64;
    for (gamma, k_d, k_r, colours, const_view, epsilon) in [
        (1.0, 1.0, 1.0, false, false, EPSILON),
        (2.2, 1.0, 1.0, true, false, EPSILON),
        (1.0, 1.3, 0.7, true, true, 0.2),
        (2.2, 0.5, 1.0, false, true, 4.0),
        (1.0, 1.0, 1.0, true, false, 0.3),
    ] {
        for cut in [n, n - 5, 8 * 131 + 3] {
            let third = [0.1f32, -0.2, 1.0];
            let b = Buffers {
                ids: &ids[..cut],
                normals: &normals[..3 * cut],
                edited: &edited[..3 * cut],
                view: if const_view { &third } else { &view[..3 * cut] },
                diffuse: &diffuse[..3 * cut],
                reflection: &reflection[..3 * cut],
                alpha_d: &alpha_d[..cut],
                alpha_r: &alpha_r[..cut],
                alpha: if colours { &alpha[..cut] } else { &[] },
                image: &image[..3 * cut],
                diffuse_color: if colours { &dcol[..3 * cut] } else { &[] },
                reflection_color: if colours { &rcol[..3 * cut] } else { &[] },
            };
            let p = Params {
                k_d,
                k_r,
                gamma,
                epsilon,
            };
            let (want, st0) = recomposite_scalar(&b, &patches, &p).unwrap();
            assert!(st0.edited > 0 && st0.masked > 0, "{st0:?}");
            let (portable, _) = recomposite_with(&b, &patches, &p, false).unwrap();
            for simd in [false, true] {
                let (got, st) = recomposite_with(&b, &patches, &p, simd).unwrap();
                assert_eq!(
                    (st.edited, st.masked),
                    (st0.edited, st0.masked),
                    "γ {gamma} simd {simd}"
                );
                for (i, (x, y)) in got.iter().zip(&want).enumerate() {
                    let d = (*x as f64 - *y as f64).abs() / (1.0 + (*y as f64).abs());
                    worst = worst.max(d);
                    assert!(
                        d <= 2e-5,
                        "value {i}: {x} vs {y} (γ {gamma}, k_D {k_d}, simd {simd})"
                    );
                    assert!(!x.is_nan(), "NaN output at {i}");
                    assert_eq!(
                        x.to_bits(),
                        portable[i].to_bits(),
                        "value {i}: AVX2 and portable paths differ"
                    );
                }
            }
            cases += 1;
        }
    }
    assert_eq!(cases, 15);
    eprintln!("largest difference from the scalar reference: {worst:.3e}");
}

/// A random frame for the [`Recompositor`] tests: (w, h, ids, normals, edited, view, the
/// shading passes, α's, I, colours) and four patches (SH + map, SH, map, nothing).
#[allow(clippy::type_complexity)]
fn session_frame(w: usize, h: usize) -> (Vec<i32>, Vec<Vec<f32>>, Vec<Vec<f32>>, Vec<Patch>) {
    let mut g = Rng(0x005e_ed0f_7e57);
    let n = w * h;
    let ids: Vec<i32> = (0..n).map(|i| ((i / 37) % 5) as i32 - 1).collect();
    let mut v3 =
        |lo: f32, hi: f32| -> Vec<f32> { (0..3 * n).map(|_| lo + (hi - lo) * g.next()).collect() };
    let normals: Vec<f32> = v3(-1.0, 1.0)
        .chunks(3)
        .flat_map(|c| [c[0], c[1], c[2].abs() + 0.3])
        .collect();
    let mut edited = normals.clone();
    for (i, x) in edited.iter_mut().enumerate() {
        if (i / 3) % 3 != 0 {
            *x += 0.2 * ((i % 7) as f32 - 3.0) / 3.0;
        }
    }
    let view: Vec<f32> = (0..n)
        .flat_map(|i| [0.01 * (i % 5) as f32, -0.1, 1.0])
        .collect();
    let threes = vec![
        v3(0.0, 2.0),
        v3(0.0, 2.0),
        v3(0.0, 3.0),
        v3(0.0, 1.0),
        v3(0.0, 1.0),
    ];
    let ones: Vec<Vec<f32>> = (0..3).map(|_| (0..n).map(|_| g.next()).collect()).collect();
    let map = |g: &mut Rng, size: usize| ParaboloidMap {
        size,
        channels: 3,
        data: (0..2 * size * size * 3).map(|_| g.next()).collect(),
    };
    let sh = |g: &mut Rng| -> [[f64; SH_COEFFS]; 3] {
        std::array::from_fn(|_| std::array::from_fn(|_| g.next() as f64 - 0.5))
    };
    let patches = vec![
        Patch {
            sh: Some(sh(&mut g)),
            env: Some(map(&mut g, 8)),
        },
        Patch {
            sh: Some(sh(&mut g)),
            env: None,
        },
        Patch {
            sh: None,
            env: Some(map(&mut g, 4)),
        },
        Patch::default(),
    ];
    let mut vecs = vec![normals, edited, view];
    vecs.extend(threes);
    (ids, vecs, ones, patches)
}

/// The session object against [`recomposite`] (the oracle): the whole frame, windows into a
/// window-shaped and a frame-shaped buffer (only the window written), ñ borrowed or kept,
/// k_D, k_R ≠ 1, γ = 2.2, new patches — the same bits.
#[test]
fn recompositor_matches_recomposite() {
    let (w, h) = (83, 29);
    let (ids, v, a, patches) = session_frame(w, h);
    let (normals, edited, view) = (&v[0], &v[1], &v[2]);
    for gamma in [1.0, 2.2] {
        let b = Buffers {
            ids: &ids,
            normals,
            edited,
            view,
            diffuse: &v[3],
            reflection: &v[4],
            alpha_d: &a[0],
            alpha_r: &a[1],
            alpha: &a[2],
            image: &v[5],
            diffuse_color: &v[6],
            reflection_color: &v[7],
        };
        let mut rc = Recompositor::new(w, h, &b, patches.clone(), gamma, EPSILON).unwrap();
        for (k_d, k_r) in [(1.0, 1.0), (1.3, 0.6)] {
            let p = Params {
                k_d,
                k_r,
                gamma,
                ..Params::default()
            };
            let (want, st0) = recomposite(&b, &patches, &p).unwrap();
            assert!(st0.edited > 0);
            // The whole frame, ñ borrowed.
            let mut out = vec![f32::NAN; 3 * w * h];
            let st = rc
                .run(&rc.full(), Some(edited), k_d, k_r, &mut out, true)
                .unwrap();
            assert_eq!((st.edited, st.masked), (st0.edited, st0.masked));
            assert!(out
                .iter()
                .zip(&want)
                .all(|(x, y)| x.to_bits() == y.to_bits()));
            // Without the per-pixel tables, and through the portable instantiation (tables
            // made by it too): the same bits.
            for (prepared, simd) in [(false, true), (true, false), (false, false)] {
                let mut other =
                    Recompositor::new(w, h, &b, patches.clone(), gamma, EPSILON).unwrap();
                other.simd = simd;
                other.set_prepared(false);
                other.set_prepared(prepared);
                assert_eq!(other.prepared_bytes() > 0, prepared);
                let mut o2 = vec![f32::NAN; 3 * w * h];
                let st2 = other
                    .run(&other.full(), Some(edited), k_d, k_r, &mut o2, true)
                    .unwrap();
                assert_eq!((st2.edited, st2.masked), (st0.edited, st0.masked));
                assert!(o2
                    .iter()
                    .zip(&want)
                    .all(|(x, y)| x.to_bits() == y.to_bits()));
            }
            // A window: ñ kept here, set from the whole frame; window- and frame-shaped out.
            let win = Window {
                rows: 3..17,
                cols: 10..71,
            };
            rc.set_edited(&win, edited, true).unwrap();
            let mut small = vec![0.0f32; 3 * 14 * 61];
            rc.run(&win, None, k_d, k_r, &mut small, false).unwrap();
            let mut big = vec![-7.0f32; 3 * w * h];
            rc.run(&win, None, k_d, k_r, &mut big, true).unwrap();
            for r in 0..h {
                for c in 0..w {
                    let i = 3 * (r * w + c);
                    let inside = win.rows.contains(&r) && win.cols.contains(&c);
                    for ch in 0..3 {
                        if inside {
                            let j = 3 * ((r - 3) * 61 + c - 10) + ch;
                            assert_eq!(small[j].to_bits(), want[i + ch].to_bits());
                            assert_eq!(big[i + ch].to_bits(), want[i + ch].to_bits());
                        } else {
                            assert_eq!(big[i + ch], -7.0, "outside the window: untouched");
                        }
                    }
                }
            }
            // Whole rows as a window, ñ given window-shaped.
            let rows = Window {
                rows: 20..29,
                cols: 0..w,
            };
            rc.set_edited(&rows, &edited[3 * 20 * w..], false).unwrap();
            let mut part = vec![0.0f32; 3 * 9 * w];
            rc.run(&rows, None, k_d, k_r, &mut part, false).unwrap();
            assert!(part
                .iter()
                .zip(&want[3 * 20 * w..])
                .all(|(x, y)| x.to_bits() == y.to_bits()));
        }
        // New patches: the oracle with the same.
        let swapped: Vec<Patch> = patches.iter().rev().cloned().collect();
        rc.set_patches(swapped.clone()).unwrap();
        let (want, _) = recomposite(
            &b,
            &swapped,
            &Params {
                gamma,
                ..Params::default()
            },
        )
        .unwrap();
        let mut out = vec![0.0f32; 3 * w * h];
        rc.run(&rc.full(), Some(edited), 1.0, 1.0, &mut out, true)
            .unwrap();
        assert!(out
            .iter()
            .zip(&want)
            .all(|(x, y)| x.to_bits() == y.to_bits()));
    }
}

/// The session's per-pixel tables with a view for the whole frame (orthographic), one that
/// cannot be normalised, and non-finite passes and normals: the same bits and counts as
/// [`recomposite`], with and without the tables, AVX2 and portable.
#[test]
fn recompositor_tables_match_recomposite_for_every_view() {
    let (w, h) = (67, 23);
    let (ids, v, a, patches) = session_frame(w, h);
    let mut v = v;
    let mut a = a;
    v[3][3 * 100 + 1] = f32::NAN; // D0
    v[4][3 * 200] = f32::INFINITY; // R0
    v[7][3 * 300 + 2] = f32::NAN; // c_R
    a[1][400] = f32::NAN; // α_R
    v[0][3 * 500] = f32::NAN; // n
    v[0][3 * 600..3 * 600 + 3].fill(0.0); // n = 0
    for view in [v[2].clone(), vec![0.1, -0.2, 1.0], vec![0.0; 3]] {
        let b = Buffers {
            ids: &ids,
            normals: &v[0],
            edited: &v[1],
            view: &view,
            diffuse: &v[3],
            reflection: &v[4],
            alpha_d: &a[0],
            alpha_r: &a[1],
            alpha: &a[2],
            image: &v[5],
            diffuse_color: &v[6],
            reflection_color: &v[7],
        };
        for gamma in [1.0, 2.2] {
            let p = Params {
                gamma,
                k_d: 1.1,
                ..Params::default()
            };
            let (want, st0) = recomposite(&b, &patches, &p).unwrap();
            assert!(st0.masked > 0);
            for (prepared, simd) in [(true, true), (true, false), (false, true)] {
                let mut rc = Recompositor::new(w, h, &b, patches.clone(), gamma, EPSILON).unwrap();
                rc.simd = simd;
                rc.set_prepared(false);
                rc.set_prepared(prepared);
                let mut out = vec![f32::NAN; 3 * w * h];
                let st = rc
                    .run(&rc.full(), Some(&v[1]), 1.1, 1.0, &mut out, true)
                    .unwrap();
                assert_eq!((st.edited, st.masked), (st0.edited, st0.masked));
                assert!(out
                    .iter()
                    .zip(&want)
                    .all(|(x, y)| x.to_bits() == y.to_bits()));
            }
        }
    }
}

/// Bad input to the session object: wrong lengths, windows outside the frame, non-finite
/// k's, bad maps — errors naming the argument; overflow refused naming the pixel, at γ = 1
/// too.
#[test]
fn recompositor_refuses_bad_input() {
    let (w, h) = (16, 8);
    let (ids, v, a, patches) = session_frame(w, h);
    let b = Buffers {
        ids: &ids,
        normals: &v[0],
        edited: &v[1],
        view: &v[2],
        diffuse: &v[3],
        reflection: &v[4],
        alpha_d: &a[0],
        alpha_r: &a[1],
        alpha: &a[2],
        image: &v[5],
        diffuse_color: &[],
        reflection_color: &[],
    };
    let arg = |e: RokebyError| match e {
        RokebyError::InvalidArgument { arg, .. } => arg,
        e => panic!("{e}"),
    };
    let e = Recompositor::new(w + 1, h, &b, patches.clone(), 1.0, EPSILON)
        .err()
        .unwrap();
    assert_eq!(arg(e), "ids");
    let short = Buffers {
        diffuse: &v[3][3..],
        ..b
    };
    let e = Recompositor::new(w, h, &short, patches.clone(), 1.0, EPSILON)
        .err()
        .unwrap();
    assert_eq!(arg(e), "diffuse");
    let e = Recompositor::new(w, h, &b, patches.clone(), f64::NAN, EPSILON)
        .err()
        .unwrap();
    assert_eq!(arg(e), "gamma");
    let mut rc = Recompositor::new(w, h, &b, patches.clone(), 1.0, EPSILON).unwrap();
    let mut out = vec![0.0f32; 3 * w * h];
    let full = rc.full();
    let e = rc
        .run(&full, Some(&v[1][3..]), 1.0, 1.0, &mut out, true)
        .err()
        .unwrap();
    assert_eq!(arg(e), "edited_normals");
    let e = rc
        .run(&full, None, 1.0, 1.0, &mut out[3..], true)
        .err()
        .unwrap();
    assert_eq!(arg(e), "out");
    let e = rc
        .run(&full, None, f64::NAN, 1.0, &mut out, true)
        .err()
        .unwrap();
    assert_eq!(arg(e), "k_d");
    for win in [
        Window {
            rows: 0..h + 1,
            cols: 0..w,
        },
        Window {
            rows: 2..2,
            cols: 0..w,
        },
        Window {
            rows: 0..h,
            cols: 5..w + 3,
        },
    ] {
        let e = rc.run(&win, None, 1.0, 1.0, &mut out, true).err().unwrap();
        assert_eq!(arg(e), "window");
        let e = rc.set_edited(&win, &v[1], true).err().unwrap();
        assert_eq!(arg(e), "window");
    }
    let bad = Patch {
        sh: None,
        env: Some(ParaboloidMap {
            size: 4,
            channels: 3,
            data: vec![0.0; 5],
        }),
    };
    assert_eq!(arg(rc.set_patches(vec![bad]).err().unwrap()), "patches");
    // k_D = 3e38 overflows float32 in eq. 5 at γ = 1 (D~ ≥ 1.2 somewhere): refused, naming a
    // pixel.
    let e = rc
        .run(&full, Some(&v[1]), 3e38, 1.0, &mut out, true)
        .err()
        .unwrap();
    assert!(e.to_string().contains("overflows"), "{e}");
}

/// Unmodified normals with k_D = k_R = 1 give I bit for bit (any γ, view, NaN inputs), on both
/// paths, and nothing is counted.
#[test]
fn recomposite_identity_is_bit_exact() {
    let mut g = Rng(0x1234_5678_9abc_def1);
    let n = 2500;
    let ids: Vec<i32> = (0..n).map(|i| (i % 4) - 1).collect();
    let v3 = |g: &mut Rng| -> Vec<f32> { (0..3 * n).map(|_| 2.0 * g.next() - 0.5).collect() };
    let normals = v3(&mut g);
    let view = v3(&mut g);
    let mut diffuse = v3(&mut g);
    diffuse[7] = f32::NAN;
    let reflection = v3(&mut g);
    let mut image = v3(&mut g);
    image[10] = f32::NAN;
    image[11] = f32::INFINITY;
    let a: Vec<f32> = (0..n).map(|_| g.next()).collect();
    let map = ParaboloidMap {
        size: 8,
        channels: 3,
        data: (0..2 * 8 * 8 * 3).map(|_| g.next()).collect(),
    };
    let sh: [[f64; SH_COEFFS]; 3] =
        std::array::from_fn(|_| std::array::from_fn(|_| g.next() as f64));
    let patches = vec![
        Patch {
            sh: Some(sh),
            env: Some(map),
        },
        Patch {
            sh: Some(sh),
            env: None,
        },
        Patch::default(),
    ];
    for gamma in [1.0, 2.2] {
        let b = Buffers {
            ids: &ids,
            normals: &normals,
            edited: &normals,
            view: &view,
            diffuse: &diffuse,
            reflection: &reflection,
            alpha_d: &a,
            alpha_r: &a,
            alpha: &a,
            image: &image,
            diffuse_color: &[],
            reflection_color: &[],
        };
        for simd in [false, true] {
            let (out, st) = recomposite_with(
                &b,
                &patches,
                &Params {
                    gamma,
                    ..Params::default()
                },
                simd,
            )
            .unwrap();
            assert_eq!((st.edited, st.masked), (0, 0));
            assert!(
                out.iter()
                    .zip(&image)
                    .all(|(x, y)| x.to_bits() == y.to_bits()),
                "γ {gamma} simd {simd}"
            );
        }
    }
}

/// `pow_lanes` against `powf`: within 1 ulp (f32) over the whole range — subnormals, huge
/// values, exponents from 1/2.2 to 10 — and powf's values for 0, ∞, negatives and NaN
/// (after the clamp to ≥ 0).
#[test]
fn pow_lanes_matches_powf() {
    let mut g = Rng(0x0bad_cafe_f00d_1234);
    for p in [1.0 / 2.2f32, 0.5, 1.0 / 1.8, 2.0, 3.3, 10.0, 1.0] {
        let mut worst = 0u32;
        for round in 0..400 {
            let mut x = [0.0f32; LANES];
            for (l, v) in x.iter_mut().enumerate() {
                // log-uniform over the positive f32 range (subnormals included) and specials.
                *v = f32::from_bits((g.next() * 0x7f7f_ffff as f32) as u32);
                if round == 0 {
                    *v = [
                        0.0,
                        -0.0,
                        -1.0,
                        f32::NAN,
                        f32::INFINITY,
                        f32::NEG_INFINITY,
                        1.0,
                        f32::MIN_POSITIVE,
                        1e-45,
                        f32::MAX,
                        2.0,
                        0.5,
                    ][l % 12];
                }
            }
            let mut y = x;
            pow_lanes(&mut y, p as f64, LANES);
            for l in 0..LANES {
                let want = x[l].max(0.0).powf(p);
                if want.is_finite() && want > 0.0 && y[l].is_finite() {
                    worst = worst.max(want.to_bits().abs_diff(y[l].to_bits()));
                } else {
                    assert_eq!(
                        y[l].to_bits(),
                        want.to_bits(),
                        "{}^{p}: {} vs {want}",
                        x[l],
                        y[l]
                    );
                }
            }
        }
        assert!(worst <= 1, "p {p}: {worst} ulp");
    }
}
