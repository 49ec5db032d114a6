//! One recompositing edit (eqs. 3–5) of bench/compositing.py's 1920×1080 frame with ten patches
//!, through `Recompositor`: for instruction counts (callgrind) and quick timings of the
//! kernel alone, without Python.
//!
//! `cargo run --release -p rokeby-core --example recomposite_edit -- [EDITS] [--gamma G] [--ortho]`
//! runs one untimed edit, then EDITS (default 20) timed ones and prints their median (wall, ms) and
//! the process's CPU time per edit (all threads; /proc, 10 ms ticks).
//! `EDITS = 0`: the set-up only (subtract its count from a run with edits under callgrind).

use rokeby_core::compositing::recomposite::{Buffers, Patch, Recompositor};
use rokeby_core::compositing::reconstruct::ParaboloidMap;
use std::time::Instant;

const TRUE_SH: [[f64; 9]; 3] = [
    [1.2, 0.3, 0.5, -0.2, 0.1, 0.05, 0.15, -0.05, 0.04],
    [1.0, 0.2, 0.45, -0.1, 0.05, 0.02, 0.1, -0.04, 0.03],
    [0.9, 0.1, 0.4, 0.0, 0.02, 0.01, 0.08, -0.02, 0.02],
];

/// CPU time of the process (all threads, user + system) in ms, from /proc (10 ms ticks); NaN
/// where there is none.
fn cpu_ms() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    // The fields after the command name (which is in parentheses): utime and stime are 14 and 15.
    let rest = stat.rsplit_once(')').map_or("", |(_, r)| r);
    let f: Vec<&str> = rest.split_whitespace().collect();
    let tick = |i: usize| {
        f.get(i)
            .and_then(|x| x.parse::<f64>().ok())
            .unwrap_or(f64::NAN)
    };
    (tick(11) + tick(12)) * 10.0
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let edits: usize = args
        .iter()
        .find(|a| !a.starts_with("--") && a.parse::<usize>().is_ok())
        .map_or(20, |a| a.parse().unwrap());
    let gamma: f64 = args
        .iter()
        .position(|a| a == "--gamma")
        .map_or(1.0, |i| args[i + 1].parse().unwrap());
    let ortho = args.iter().any(|a| a == "--ortho");
    let (w, h, patches, env_size) = (1920usize, 1080usize, 10usize, 128usize);
    let n = w * h;
    // bench/compositing.py's hd_frame, with a xorshift for numpy's normals.
    let mut s = 0x9e37_79b9_7f4a_7c15u64;
    let mut rnd = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        ((s >> 40) as f32 / (1u64 << 24) as f32) * 2.0
    };
    let mut ids = vec![-1i32; n];
    for r in 80..h - 80 {
        for c in 0..w {
            ids[r * w + c] = (c * patches / w) as i32;
        }
    }
    let mut nrm = Vec::with_capacity(3 * n);
    for r in 0..h {
        for c in 0..w {
            let v = [(c as f32 / 37.0).sin(), (r as f32 / 53.0).cos(), 1.2];
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            nrm.extend(v.map(|x| x / l));
        }
    }
    let mut edited = nrm.clone();
    for px in 0..w * (h / 2) {
        edited[3 * px + 2] *= 0.5;
    }
    let d0: Vec<f32> = (0..3 * n).map(|_| rnd()).collect();
    let r0: Vec<f32> = (0..3 * n).map(|_| rnd()).collect();
    let img: Vec<f32> = d0.iter().zip(&r0).map(|(a, b)| a + b).collect();
    let a = vec![0.9f32; n];
    let view: Vec<f32> = if ortho {
        vec![0.0, 0.0, 1.0]
    } else {
        (0..n).flat_map(|_| [0.0, 0.0, 1.0]).collect()
    };
    let pts: Vec<Patch> = (0..patches)
        .map(|_| Patch {
            sh: Some(TRUE_SH),
            env: Some(ParaboloidMap {
                size: env_size,
                channels: 3,
                data: (0..2 * env_size * env_size * 3).map(|_| rnd()).collect(),
            }),
        })
        .collect();
    let b = Buffers {
        ids: &ids,
        normals: &nrm,
        edited: &nrm,
        view: &view,
        diffuse: &d0,
        reflection: &r0,
        alpha_d: &a,
        alpha_r: &a,
        alpha: &a,
        image: &img,
        diffuse_color: &d0,
        reflection_color: &r0,
    };
    let t = Instant::now();
    let rc = Recompositor::new(
        w,
        h,
        &b,
        pts,
        gamma,
        rokeby_core::compositing::recomposite::EPSILON,
    )
    .unwrap();
    let setup = t.elapsed().as_secs_f64() * 1e3;
    let mut out = vec![0.0f32; 3 * n];
    let win = rc.full();
    if edits == 0 {
        println!("set-up {setup:.1} ms");
        return;
    }
    let st = rc
        .run(&win, Some(&edited), 1.0, 1.0, &mut out, true)
        .unwrap();
    let mut ts = Vec::new();
    let cpu0 = cpu_ms();
    for _ in 0..edits {
        let t = Instant::now();
        rc.run(&win, Some(&edited), 1.0, 1.0, &mut out, true)
            .unwrap();
        ts.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let cpu = (cpu_ms() - cpu0) / edits as f64;
    ts.sort_by(f64::total_cmp);
    let sum: f64 = out.iter().map(|&x| x as f64).sum();
    println!(
        "set-up {setup:.1} ms; edit median {:.2} ms (min {:.2}) of {edits}, CPU {cpu:.2} ms per edit (all threads); edited {} masked {}; checksum {sum:.6}",
        ts[edits / 2], ts[0], st.edited, st.masked
    );
}
