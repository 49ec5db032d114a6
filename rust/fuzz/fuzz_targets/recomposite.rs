//! recomposite (eqs. 3–5) and eval_diffuse on small random buffers and patches. Never a
//! panic; accepted input gives H·W×3 output; pixels whose normal is unedited (k_D = k_R = 1) and
//! pixels outside every patch are returned exactly; finite bounded input gives finite output.
#![no_main]
mod common;
use common::Input;
use libfuzzer_sys::fuzz_target;
use rokeby_core::compositing::recomposite::{eval_diffuse, recomposite, Buffers, Params, Patch};
use rokeby_core::compositing::reconstruct::ParaboloidMap;
use rokeby_core::compositing::sh::SH_COEFFS;

fuzz_target!(|data: &[u8]| {
    let mut inp = Input::new(data);
    let n = inp.below(12);
    let adversarial = inp.bool();
    let npatch = inp.below(3);
    let mut patches = Vec::new();
    for _ in 0..npatch {
        let sh = if inp.bool() { Some(std::array::from_fn::<[f64; SH_COEFFS], 3, _>(|_| std::array::from_fn(|_| inp.finite(2.0)))) } else { None };
        let env = if inp.bool() {
            let mut m = ParaboloidMap::new(inp.below(5), 3);
            let len = m.data.len();
            m.data = inp.f32s_finite(len, 5.0);
            Some(m)
        } else {
            None
        };
        patches.push(Patch { sh, env });
    }
    let ids: Vec<i32> = (0..n).map(|_| inp.below(npatch + 2) as i32 - 1).collect();
    let vec3s = |inp: &mut Input, adv: bool| if adv { inp.f32s(3 * n, 2.0) } else { inp.f32s_finite(3 * n, 1.0) };
    let normals = vec3s(&mut inp, adversarial);
    let edited: Vec<f32> = (0..3 * n).map(|k| if k % 3 == 0 && inp.byte() % 2 == 0 { normals[k] } else if inp.byte() % 3 == 0 { normals[k] } else { inp.finite(1.0) as f32 }).collect();
    let edited = if inp.bool() { normals.clone() } else { edited };
    let view = if inp.bool() { vec3s(&mut inp, adversarial)[..3.min(3 * n)].to_vec() } else { vec3s(&mut inp, adversarial) };
    let view = if view.len() != 3 && view.len() != 3 * n { vec![0.0, 0.0, 1.0] } else { view };
    let diffuse = vec3s(&mut inp, adversarial);
    let reflection = vec3s(&mut inp, adversarial);
    let image = vec3s(&mut inp, adversarial);
    let opt1 = |inp: &mut Input| if inp.bool() { Vec::new() } else { (0..n).map(|_| inp.range(0.0, 1.0) as f32).collect() };
    let (alpha_d, alpha_r, alpha) = (opt1(&mut inp), opt1(&mut inp), opt1(&mut inp));
    let optc = |inp: &mut Input| if inp.bool() { Vec::new() } else { inp.f32s_finite(3 * n, 1.0).iter().map(|x| x.abs()).collect() };
    let (diffuse_color, reflection_color) = (optc(&mut inp), optc(&mut inp));
    let p = if adversarial {
        Params { k_d: inp.f64_in(3.0), k_r: inp.f64_in(3.0), gamma: inp.f64_in(3.0), epsilon: inp.f64_in(1.0) }
    } else if inp.bool() {
        Params::default()
    } else {
        Params { k_d: inp.range(0.0, 3.0), k_r: inp.range(0.0, 3.0), gamma: inp.range(0.3, 3.0), epsilon: inp.range(1e-4, 4.0) }
    };
    let b = Buffers {
        ids: &ids,
        normals: &normals,
        edited: &edited,
        view: &view,
        diffuse: &diffuse,
        reflection: &reflection,
        alpha_d: &alpha_d,
        alpha_r: &alpha_r,
        alpha: &alpha,
        image: &image,
        diffuse_color: &diffuse_color,
        reflection_color: &reflection_color,
    };
    if let Ok((out, stats)) = recomposite(&b, &patches, &p) {
        assert_eq!(out.len(), 3 * n);
        assert!(stats.masked + stats.edited <= n);
        for i in 0..n {
            let px = &out[3 * i..3 * i + 3];
            let img = &image[3 * i..3 * i + 3];
            let outside = ids[i] < 0 || ids[i] as usize >= patches.len();
            let same = normals[3 * i..3 * i + 3] == edited[3 * i..3 * i + 3] && p.k_d == 1.0 && p.k_r == 1.0;
            if outside || same {
                assert!(px.iter().zip(img).all(|(a, b)| a.to_bits() == b.to_bits()), "pixel {i} changed: {img:?} → {px:?}");
            }
            if !adversarial {
                assert!(px.iter().all(|x| x.is_finite()), "pixel {i} not finite: {px:?} (image {img:?})");
            }
        }
    }
    if let Ok(d) = eval_diffuse(&ids, &normals, &patches) {
        assert_eq!(d.len(), 3 * n);
        if !adversarial {
            assert!(d.iter().all(|x| x.is_finite()));
        }
    }
});
