//! A radix heap (Ahuja, Mehlhorn, Orlin & Tarjan 1990) for Dijkstra's monotone queue.
//!
//! Keys are non-negative f32 distances compared by their bit patterns (for non-negative floats
//! the order of the bits is the order of the values). Dijkstra pushes only keys at or above the
//! last one popped, which is all a radix heap needs: a push is O(1), a pop amortised O(log C) by
//! redistributing one bucket — no comparisons between entries that are never popped, unlike a
//! binary heap. Ties pop in no particular order.

/// Entries: (key bits, vertex).
pub(crate) struct RadixHeap {
    last: u32,
    len: usize,
    buckets: [Vec<(u32, u32)>; 33],
}

#[inline]
fn bucket(key: u32, last: u32) -> usize {
    (32 - (key ^ last).leading_zeros()) as usize
}

impl RadixHeap {
    pub(crate) fn new() -> Self {
        RadixHeap {
            last: 0,
            len: 0,
            buckets: std::array::from_fn(|_| Vec::new()),
        }
    }

    /// Pushes `v` with distance `d` (≥ 0, and not below the last key popped).
    #[inline]
    pub(crate) fn push(&mut self, d: f32, v: u32) {
        let key = d.max(0.0).to_bits().max(self.last);
        self.buckets[bucket(key, self.last)].push((key, v));
        self.len += 1;
    }

    /// The entry of smallest key (its key as f32, and the vertex).
    #[inline]
    pub(crate) fn pop(&mut self) -> Option<(f32, u32)> {
        if self.len == 0 {
            return None;
        }
        if self.buckets[0].is_empty() {
            let i = (1..33).find(|&i| !self.buckets[i].is_empty())?;
            let moved = std::mem::take(&mut self.buckets[i]);
            self.last = moved.iter().map(|e| e.0).min().unwrap_or(self.last);
            for &(k, v) in &moved {
                self.buckets[bucket(k, self.last)].push((k, v));
            }
            // Keep the emptied bucket's allocation for later pushes.
            let mut moved = moved;
            moved.clear();
            if self.buckets[i].is_empty() {
                self.buckets[i] = moved;
            }
        }
        self.len -= 1;
        self.buckets[0].pop().map(|(k, v)| (f32::from_bits(k), v))
    }
}

#[cfg(test)]
mod tests {
    use super::RadixHeap;

    #[test]
    fn pops_in_order_while_pushes_stay_monotone() {
        let mut h = RadixHeap::new();
        let mut x = 12345u64;
        let mut rnd = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x % 1000) as f32 / 7.0
        };
        for i in 0..100 {
            h.push(rnd(), i);
        }
        let mut last = 0.0f32;
        let mut n = 0;
        while let Some((k, v)) = h.pop() {
            assert!(k >= last, "{k} after {last}");
            last = k;
            n += 1;
            if v < 5000 {
                h.push(k + rnd(), v + 100);
            }
        }
        assert!(n > 100);
    }
}
