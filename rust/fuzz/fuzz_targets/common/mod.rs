//! Shared input decoding for the fuzz targets: a byte stream turned into numbers that favour
//! adversarial values (NaN, ±inf, ±0, huge, tiny) next to ordinary ones.
#![allow(dead_code)]
use glam::{DVec2, DVec3};

pub struct Input<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Input<'a> {
    pub fn new(data: &'a [u8]) -> Self {
        Input { data, pos: 0 }
    }
    pub fn byte(&mut self) -> u8 {
        let b = self.data.get(self.pos).copied().unwrap_or(0);
        self.pos += 1;
        b
    }
    pub fn u16(&mut self) -> u16 {
        u16::from_le_bytes([self.byte(), self.byte()])
    }
    /// 0..n (0 when n is 0).
    pub fn below(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            self.u16() as usize % n
        }
    }
    pub fn bool(&mut self) -> bool {
        self.byte() & 1 == 1
    }
    /// An f64 that is adversarial one time in eight, else in [-scale, scale].
    pub fn f64_in(&mut self, scale: f64) -> f64 {
        let tag = self.byte();
        if tag % 8 == 0 {
            return match (tag / 8) % 10 {
                0 => f64::NAN,
                1 => f64::INFINITY,
                2 => f64::NEG_INFINITY,
                3 => 0.0,
                4 => -0.0,
                5 => 1e300,
                6 => -1e300,
                7 => 1e-300,
                8 => f64::MIN_POSITIVE / 4.0,
                _ => 1e30,
            };
        }
        let x = self.u16() as f64 / 65535.0;
        (2.0 * x - 1.0) * scale
    }
    /// A finite f64 in [-scale, scale].
    pub fn finite(&mut self, scale: f64) -> f64 {
        let x = self.u16() as f64 / 65535.0;
        (2.0 * x - 1.0) * scale
    }
    /// A finite f64 in [lo, hi].
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * (self.u16() as f64 / 65535.0)
    }
    pub fn v3(&mut self, scale: f64) -> DVec3 {
        DVec3::new(self.f64_in(scale), self.f64_in(scale), self.f64_in(scale))
    }
    pub fn v3_finite(&mut self, scale: f64) -> DVec3 {
        DVec3::new(self.finite(scale), self.finite(scale), self.finite(scale))
    }
    pub fn v2(&mut self, scale: f64) -> DVec2 {
        DVec2::new(self.f64_in(scale), self.f64_in(scale))
    }
    pub fn v2_finite(&mut self, scale: f64) -> DVec2 {
        DVec2::new(self.finite(scale), self.finite(scale))
    }
    pub fn f32s(&mut self, n: usize, scale: f64) -> Vec<f32> {
        (0..n).map(|_| self.f64_in(scale) as f32).collect()
    }
    pub fn f32s_finite(&mut self, n: usize, scale: f64) -> Vec<f32> {
        (0..n).map(|_| self.finite(scale) as f32).collect()
    }
}

/// An octahedron (closed, outward-oriented), scaled by `s` and shifted by `c`, with each vertex
/// jittered by up to `jitter`.
pub fn octahedron(inp: &mut Input, s: f64, c: DVec3, jitter: f64) -> (Vec<f32>, Vec<i64>) {
    let base = [[1., 0., 0.], [-1., 0., 0.], [0., 1., 0.], [0., -1., 0.], [0., 0., 1.], [0., 0., -1.]];
    let mut v = Vec::new();
    for p in base {
        for k in 0..3 {
            v.push((p[k] * s + [c.x, c.y, c.z][k] + inp.finite(jitter)) as f32);
        }
    }
    let f: Vec<i64> = vec![0, 2, 4, 2, 1, 4, 1, 3, 4, 3, 0, 4, 2, 0, 5, 1, 2, 5, 3, 1, 5, 0, 3, 5];
    (v, f)
}

/// A UV sphere (closed, outward-oriented) of `rings` × `segs`, radius `r`, centre `c`.
pub fn uv_sphere(rings: usize, segs: usize, r: f64, c: DVec3) -> (Vec<f32>, Vec<i64>) {
    let rings = rings.max(2);
    let segs = segs.max(3);
    let mut v = vec![c.x as f32, c.y as f32, (c.z + r) as f32];
    for i in 1..rings {
        let th = std::f64::consts::PI * i as f64 / rings as f64;
        for j in 0..segs {
            let ph = std::f64::consts::TAU * j as f64 / segs as f64;
            v.extend([(c.x + r * th.sin() * ph.cos()) as f32, (c.y + r * th.sin() * ph.sin()) as f32, (c.z + r * th.cos()) as f32]);
        }
    }
    v.extend([c.x as f32, c.y as f32, (c.z - r) as f32]);
    let bottom = (1 + (rings - 1) * segs) as i64;
    let idx = |i: usize, j: usize| (1 + (i - 1) * segs + j % segs) as i64;
    let mut f = Vec::new();
    for j in 0..segs {
        f.extend([0, idx(1, j), idx(1, j + 1)]);
    }
    for i in 1..rings - 1 {
        for j in 0..segs {
            let (a, b, c2, d) = (idx(i, j), idx(i, j + 1), idx(i + 1, j), idx(i + 1, j + 1));
            f.extend([a, c2, d, a, d, b]);
        }
    }
    for j in 0..segs {
        f.extend([bottom, idx(rings - 1, j + 1), idx(rings - 1, j)]);
    }
    (v, f)
}
