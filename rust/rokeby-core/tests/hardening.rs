//! The error contract in the core: sizes a caller or a file controls are bounded before
//! anything is allocated (OutOfMemory, never an abort), long loops are clipped to the data and
//! cancellable, and finite input never gives NaN or inf.

use rokeby_core::compositing::normals::{self, Frame};
use rokeby_core::compositing::reconstruct::{self, ParaboloidMap};
use rokeby_core::envmaps::envmap::{EnvMap, Layout};
use rokeby_core::envmaps::prefilter::{self, Lobe, PrefilterParams};
use rokeby_core::geometry::geodesic::{interpolate, SurfacePoint};
use rokeby_core::{cancel, compositing::sh, RokebyError};
use std::sync::Mutex;
use std::time::Instant;

/// The cancel flag is process-wide: tests that run cancellable work hold this lock so that the
/// cancel test cannot stop them.
static CANCELLABLE: Mutex<()> = Mutex::new(());

#[test]
fn an_unreachable_vertex_with_zero_weight_does_not_poison_the_point() {
    let faces = [[0usize, 1, 2]];
    let at_edge = [SurfacePoint {
        face: 0,
        bary: [0.5, 0.5, 0.0],
    }];
    let v = interpolate(&[1.0, 3.0, f32::INFINITY], 3, &faces, &at_edge).unwrap();
    assert_eq!(v, vec![2.0]);
}

#[test]
fn interpolation_that_overflows_float32_is_an_error() {
    let faces = [[0usize, 1, 2]];
    let p = [SurfacePoint {
        face: 0,
        bary: [0.6, 0.6, -0.2],
    }];
    let e = interpolate(&[3e38, 3e38, 0.0], 3, &faces, &p).unwrap_err();
    assert!(e.to_string().starts_with("values:"), "{e}");
}

#[test]
fn huge_outputs_are_out_of_memory_not_aborts() {
    let e = normals::noise_decal(1 << 32, 1 << 32, 8.0, 2, 1, (0.0, 0.0), 10.0).unwrap_err();
    assert!(matches!(e, RokebyError::OutOfMemory { .. }), "{e:?}");
    let e = normals::noise_decal(100_000, 100_000, 8.0, 2, 1, (0.0, 0.0), 10.0);
    // 40 GB: over a machine of this project's size (24 GiB); on a bigger one it may succeed.
    if let Err(e) = e {
        assert!(matches!(e, RokebyError::OutOfMemory { .. }), "{e:?}");
    }
}

#[test]
fn sh_eval_refuses_zero_normals_instead_of_nan() {
    let c = [[1.0f64; 9]];
    let e = sh::eval_many(&c, &[0.0, 0.0, 1.0, 0.0, 0.0, 0.0]).unwrap_err();
    assert_eq!(
        e.to_string(),
        "normals: normal 1 is zero or not finite: it has no direction"
    );
    let ok = sh::eval_many(&c, &[0.0, 0.0, 2.0]).unwrap();
    assert!(ok.iter().all(|x| x.is_finite()));
}

#[test]
fn reflect_dirs_gives_zero_for_zero_vectors_and_nan_only_for_nan() {
    let n = [0.0f32, 0.0, 1.0, 0.0, 0.0, 0.0, f32::NAN, 0.0, 1.0];
    let r = reconstruct::reflect_dirs(&n, &[0.0, 0.0, 1.0]).unwrap();
    assert_eq!(&r[0..3], &[0.0, 0.0, 1.0]);
    assert_eq!(&r[3..6], &[0.0, 0.0, 0.0]);
    assert!(r[6..9].iter().all(|x| x.is_nan()));
    let z = reconstruct::reflect_dirs(&n[..3], &[0.0, 0.0, 0.0]).unwrap();
    assert_eq!(z, vec![0.0, 0.0, 0.0]);
}

fn noisy_map(s: usize) -> (ParaboloidMap, ParaboloidMap) {
    let mut data = vec![0.0f32; 2 * s * s * 3];
    let mut pos = vec![0.0f32; 2 * s * s * 2];
    let mut x = 12345u64;
    for (k, d) in data.iter_mut().enumerate() {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        *d = ((x >> 33) % 1000) as f32 / 1000.0 + (k % 7) as f32;
    }
    for (k, p) in pos.iter_mut().enumerate() {
        x = x
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        *p = ((x >> 33) % 1000) as f32 / 100.0 * ((k / 2) % 3) as f32;
    }
    (
        ParaboloidMap {
            size: s,
            channels: 3,
            data,
        },
        ParaboloidMap {
            size: s,
            channels: 2,
            data: pos,
        },
    )
}

#[test]
fn a_huge_blur_sigma_is_clipped_to_the_map_and_returns() {
    let _g = CANCELLABLE.lock().unwrap_or_else(|e| e.into_inner());
    let (mut a, pos) = noisy_map(24);
    let mut b = a.clone();
    let t = Instant::now();
    let na = reconstruct::regularize(&mut a, &pos, 1e9).unwrap();
    let nb = reconstruct::regularize(&mut b, &pos, 24.0).unwrap();
    // σ above the map's size is the map's size: the same result, in bounded time (σ = 1e9 never
    // returned before).
    assert_eq!(na, nb);
    assert_eq!(a.data, b.data);
    assert!(a.data.iter().all(|x| x.is_finite()));
    assert!(t.elapsed().as_secs() < 60);
}

/// The whole-window sum of `normals::bilateral`'s documented formula, for one pixel.
fn bilateral_full(
    n: &[f32],
    d: &[f32],
    w: usize,
    h: usize,
    i: usize,
    sigma_s: f64,
    sigma_d: f64,
) -> [f64; 2] {
    let r = ((2.0 * sigma_s).ceil() as isize).max(1);
    let (y, x) = ((i / w) as isize, (i % w) as isize);
    let dp = d[i] as f64;
    let (mut ax, mut ay, mut ws) = (0.0, 0.0, 0.0);
    for dy in -r..=r {
        for dx in -r..=r {
            let (yy, xx) = (y + dy, x + dx);
            if yy < 0 || xx < 0 || yy >= h as isize || xx >= w as isize {
                continue;
            }
            let q = yy as usize * w + xx as usize;
            let rel = (d[q] as f64 - dp) / dp.abs().max(1e-6) / sigma_d;
            let wt = (-((dx * dx + dy * dy) as f64) / (2.0 * sigma_s * sigma_s)).exp()
                * (-0.5 * rel * rel).exp();
            ax += wt * n[3 * q] as f64;
            ay += wt * n[3 * q + 1] as f64;
            ws += wt;
        }
    }
    [ax / ws, ay / ws]
}

#[test]
fn a_wide_bilateral_window_is_sampled_and_stays_close_to_the_full_sum() {
    let _g = CANCELLABLE.lock().unwrap_or_else(|e| e.into_inner());
    let (w, h) = (64usize, 56usize);
    let mut n = vec![0.0f32; w * h * 3];
    let mut d = vec![0.0f32; w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let (a, b) = ((x as f32 * 0.3).sin() * 0.3, (y as f32 * 0.2).cos() * 0.3);
            n[3 * i..3 * i + 3].copy_from_slice(&[a, b, (1.0 - a * a - b * b).sqrt()]);
            d[i] = 5.0 + 0.01 * x as f32;
        }
    }
    let f = Frame {
        width: w,
        height: h,
        mask: None,
    };
    for sigma in [normals::EXACT_SIGMA_S, 12.0, 20.0] {
        let out = normals::bilateral(&n, &f, &d, sigma, 0.05).unwrap();
        let mut worst = 0.0f64;
        for i in (0..w * h).step_by(37) {
            let want = bilateral_full(&n, &d, w, h, i, sigma, 0.05);
            worst = worst
                .max((out[3 * i] as f64 - want[0]).abs())
                .max((out[3 * i + 1] as f64 - want[1]).abs());
        }
        // whole windows are the formula; sampled ones stay within about a degree of it
        let tol = if sigma <= normals::EXACT_SIGMA_S {
            1e-6
        } else {
            0.02
        };
        assert!(worst < tol, "σ_s = {sigma}: off the full window by {worst}");
    }
    let t = Instant::now();
    let wide = normals::bilateral(&n, &f, &d, normals::MAX_SIGMA_S, 0.05).unwrap();
    assert!(wide.iter().all(|x| x.is_finite()));
    assert!(t.elapsed().as_secs() < 30);
}

#[test]
fn too_many_prefilter_lobes_are_refused_before_computing() {
    let _g = CANCELLABLE.lock().unwrap_or_else(|e| e.into_inner());
    let env = EnvMap::new(Layout::LatLong, 8, 16, 3, vec![0.5; 8 * 16 * 3], "image").unwrap();
    let lobes: Vec<Lobe> = (0..20_000)
        .map(|i| Lobe::ggx_roughness((i % 10) as f64 / 10.0).unwrap())
        .collect();
    let e = prefilter::prefilter(
        &env,
        &lobes,
        &PrefilterParams {
            texels_per_radius: 6.0,
            tail: 1e-5,
        },
    )
    .unwrap_err();
    assert!(e.to_string().starts_with("params: at most"), "{e}");
}

#[test]
fn a_cancel_request_stops_long_work_with_cancelled() {
    let _g = CANCELLABLE.lock().unwrap_or_else(|e| e.into_inner());
    let (mut a, pos) = noisy_map(32);
    cancel::request();
    let e = reconstruct::regularize(&mut a, &pos, 30.0).unwrap_err();
    cancel::reset();
    assert_eq!(e, RokebyError::Cancelled);
    assert!(reconstruct::regularize(&mut a, &pos, 3.0).is_ok());
}
