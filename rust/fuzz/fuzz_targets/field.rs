//! Field::new, rotation_field_as and edited_directions on arbitrary constraint rows, points,
//! regions and distances (NaN, inf, huge, tiny, coincident). Errors are fine; panics, and
//! non-finite output from finite accepted input, are bugs.
#![no_main]
use libfuzzer_sys::fuzz_target;
use rokeby_core::reflection::field::{Distances, Field, FieldOutput};
use rokeby_core::reflection::polar::PolarMethod;
use rokeby_core::reflection::region::Region;

fn floats(data: &[u8]) -> Vec<f32> {
    data.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect()
}

fuzz_target!(|data: &[u8]| {
    if data.len() < 4 {
        return;
    }
    let (k, n, mode) = ((data[0] % 5) as usize, 1 + (data[1] % 8) as usize, data[2]);
    let f = floats(&data[4..]);
    if f.len() < 9 * k + 6 * n {
        return;
    }
    let rows = &f[..9 * k];
    let pts = &f[9 * k..9 * k + 3 * n];
    let nrm = &f[9 * k + 3 * n..9 * k + 6 * n];
    let rest = &f[9 * k + 6 * n..];
    let mut regions = Vec::new();
    if mode & 1 == 1 && rest.len() >= 5 {
        if let Ok(r) = Region::euclidean([rest[0] as f64, rest[1] as f64, rest[2] as f64], rest[3] as f64, rest[4] as f64, "fuzz") {
            regions.push(r);
        }
    }
    if mode & 2 == 2 && rest.len() >= 5 + n + k {
        if let Ok(r) = Region::per_point(rest[5..5 + n].to_vec(), rest[5 + n..5 + n + k].to_vec(), n, k, "fuzz") {
            regions.push(r);
        }
    }
    let given: Vec<f32>;
    let dist = if mode & 4 == 4 && rest.len() >= k * n {
        given = rest[rest.len() - k * n..].to_vec();
        Distances::Given(&given)
    } else {
        Distances::Euclidean
    };
    let Ok(field) = Field::new(rows, regions) else { return };
    let polar = if mode & 8 == 8 { PolarMethod::Svd } else { PolarMethod::Iterative };
    let finite = rows.iter().chain(pts).all(|x| x.is_finite());
    if let Ok(q) = field.rotation_field_as(pts, dist, None, polar, FieldOutput::Quaternion) {
        assert_eq!(q.len(), 4 * n);
        if finite {
            assert!(q.iter().all(|x| x.is_finite()), "non-finite quaternion from finite input");
        }
    }
    let eye = [rest.first().copied().unwrap_or(0.0) as f64, -5.0, 0.5];
    if let Ok(e) = field.edited_directions(pts, nrm, eye, Distances::Euclidean, polar, n) {
        assert_eq!(e.len(), 3 * n);
    }
});
