//! A radix heap (Ahuja, Mehlhorn, Orlin & Tarjan 1990) for Dijkstra's monotone queue.
//!
//! Keys are u32: either non-negative f32 distances compared by their bit patterns (for
//! non-negative floats the order of the bits is the order of the values; [`RadixHeap::push`],
//! [`RadixHeap::pop`]), or distances quantised by the caller ([`RadixHeap::push_key`]). Dijkstra
//! pushes only keys at or above the last one popped, which is all a radix heap needs: a push is
//! O(1), a pop amortised O(log C) by redistributing one bucket — no comparisons between entries
//! that are never popped, unlike a binary heap. An entry moves to a lower bucket at most once per
//! bit in which its key differs from the last key popped, so keys that differ in few bits (a
//! coarse quantisation) cost less than f32 bit patterns, whose low mantissa bits all differ.
//! Ties pop in no particular order.
//!
//! Both Dijkstras (the edge graph's and the saddle vertex graph's, [`crate::geometry::geodesic`]) use the
//! bucket queue below; the radix heap orders the exact method's windows ([`crate::geometry::exact`]) and
//! the plain Dijkstras that the unit tests keep as oracles.

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

    /// Empties the heap, keeping its buckets' allocations (for a heap reused between queries).
    pub(crate) fn clear(&mut self) {
        self.last = 0;
        self.len = 0;
        for b in &mut self.buckets {
            b.clear();
        }
    }

    /// Pushes `v` with distance `d` (≥ 0, and not below the last key popped).
    #[cfg(test)]
    #[inline]
    pub(crate) fn push(&mut self, d: f32, v: u32) {
        self.push_key(d.max(0.0).to_bits(), v);
    }

    /// The entry of smallest key (its key as f32, and the vertex).
    #[cfg(test)]
    #[inline]
    pub(crate) fn pop(&mut self) -> Option<(f32, u32)> {
        self.pop_key().map(|(k, v)| (f32::from_bits(k), v))
    }

    /// Pushes `v` with key `key` (keys below the last one popped are raised to it).
    #[inline]
    pub(crate) fn push_key(&mut self, key: u32, v: u32) {
        let key = key.max(self.last);
        self.buckets[bucket(key, self.last)].push((key, v));
        self.len += 1;
    }

    /// The entry of smallest key.
    #[inline]
    pub(crate) fn pop_key(&mut self) -> Option<(u32, u32)> {
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
        self.buckets[0].pop()
    }
}

/// A bucket queue (Dial 1969) over a window of integer keys: an array of buckets indexed by key
/// modulo the window, for Dijkstra with quantised keys where every edge spans fewer keys than the
/// window ([`crate::geometry::geodesic`]). Entries never move: a push is one append, a pop takes from the
/// current bucket or steps to the next key. Keys at or beyond the window's end (seeds far from
/// the first one popped, edges longer than the window) wait in an overflow list, moved into the
/// buckets as the window reaches them. Entries of the same key pop in no particular order.
pub(crate) struct BucketQueue {
    /// The current key (u64: keys may saturate at u32::MAX and the window runs past it).
    cur: u64,
    mask: u64,
    buckets: Vec<Vec<u32>>,
    in_window: usize,
    overflow: Vec<(u32, u32)>,
    /// The smallest key in `overflow` (u64::MAX when empty).
    overflow_min: u64,
}

impl BucketQueue {
    /// A queue whose window spans at least `span` keys (rounded up to a power of two).
    pub(crate) fn new(span: usize) -> Self {
        let n = span.max(2).next_power_of_two();
        BucketQueue {
            cur: 0,
            mask: n as u64 - 1,
            buckets: (0..n).map(|_| Vec::new()).collect(),
            in_window: 0,
            overflow: Vec::new(),
            overflow_min: u64::MAX,
        }
    }

    /// Empties the queue for a new run, keeping the buckets' allocations.
    pub(crate) fn clear(&mut self) {
        self.cur = 0;
        if self.in_window > 0 {
            self.buckets.iter_mut().for_each(Vec::clear);
        }
        self.in_window = 0;
        self.overflow.clear();
        self.overflow_min = u64::MAX;
    }

    /// Pushes `v` with key `key` (keys below the last one popped are raised to it).
    #[inline]
    pub(crate) fn push(&mut self, key: u32, v: u32) {
        let key = (key as u64).max(self.cur);
        if key <= self.cur + self.mask {
            self.buckets[(key & self.mask) as usize].push(v);
            self.in_window += 1;
        } else {
            self.overflow.push((key as u32, v));
            self.overflow_min = self.overflow_min.min(key);
        }
    }

    /// An entry of smallest key (the key, and the vertex).
    #[inline]
    pub(crate) fn pop(&mut self) -> Option<(u32, u32)> {
        loop {
            if self.in_window > 0 {
                if let Some(v) = self.buckets[(self.cur & self.mask) as usize].pop() {
                    self.in_window -= 1;
                    return Some((self.cur as u32, v));
                }
                self.cur += 1;
            } else if self.overflow_min != u64::MAX {
                self.cur = self.overflow_min;
            } else {
                return None;
            }
            if self.overflow_min <= self.cur + self.mask {
                self.refill();
            }
        }
    }

    /// The (up to) `n` entries that [`BucketQueue::pop`] would return next, last first, as far as
    /// they are in the current key's bucket (pushes in between may change them): for prefetching
    /// their data while the current one is processed.
    #[inline]
    pub(crate) fn peek(&self, n: usize) -> &[u32] {
        let b = &self.buckets[(self.cur & self.mask) as usize];
        &b[b.len().saturating_sub(n)..]
    }

    /// Moves the overflow entries that the window now covers into their buckets.
    fn refill(&mut self) {
        let end = self.cur + self.mask;
        let mut min = u64::MAX;
        let (buckets, mask) = (&mut self.buckets, self.mask);
        let mut moved = 0;
        self.overflow.retain(|&(k, v)| {
            let k = k as u64;
            if k <= end {
                buckets[(k & mask) as usize].push(v);
                moved += 1;
                false
            } else {
                min = min.min(k);
                true
            }
        });
        self.in_window += moved;
        self.overflow_min = min;
    }
}

#[cfg(test)]
mod tests {
    use super::{BucketQueue, RadixHeap};

    /// Random monotone runs (pushes at or above the last key popped, some far beyond the window)
    /// pop every entry once, in key order.
    #[test]
    fn bucket_queue_pops_in_key_order_with_overflow() {
        let mut x = 777u64;
        let mut rnd = move |m: u64| {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x % m) as u32
        };
        let mut q = BucketQueue::new(8);
        for round in 0..3 {
            q.clear();
            let mut pushed = 0;
            for i in 0..50 {
                q.push(rnd(100), i);
                pushed += 1;
            }
            q.push(u32::MAX, 999);
            pushed += 1;
            let (mut last, mut popped) = (0u32, 0);
            while let Some((k, v)) = q.pop() {
                assert!(k >= last, "round {round}: {k} after {last}");
                last = k;
                popped += 1;
                if v < 3000 && k < u32::MAX {
                    // Mostly short steps (inside the window), some long ones (overflow).
                    let step = if rnd(10) == 0 { 20 + rnd(50) } else { rnd(8) };
                    q.push(k + step, v + 60);
                    pushed += 1;
                }
            }
            assert_eq!(popped, pushed);
            assert_eq!(last, u32::MAX);
        }
    }

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
