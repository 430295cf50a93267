//! Quadtree distribution of key-point candidates (ORB-SLAM2's `DistributeOctTree`), in fixed
//! memory.
//!
//! The detection area is cut into `round(w/h)` vertical strips; then nodes holding more than
//! one candidate are split into four quadrants (empty children are dropped) until the number
//! of nodes reaches the level's quota `n` or nothing splits any more. While a whole round of
//! splits could overshoot `n`, the biggest nodes are split first and splitting stops as soon as
//! `n` is reached (so a level may end with up to `n + 3` nodes, as in ORB-SLAM2). Each node then
//! contributes its strongest candidate. The effect: features spread over the image instead of
//! piling up on the most textured region.
//!
//! Fixed memory: a node is a rectangle plus a range of the caller's candidate slice, which is
//! partitioned in place into the four quadrants when a node splits; node storage is `[Node;
//! CAP]`. Node counts stay below `max(n + 3, 4·strips)`, so `CAP >= quota + 3` suffices; if it
//! does not, splitting stops early and the event is reported, never a panic.
//!
//! Determinism: ORB-SLAM2 breaks ties between equally big nodes by heap address; here by node
//! index, and candidates are ordered by a total key before the first split.

/// A FAST corner that survived non-maximum suppression, in level pixel coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Candidate {
    /// Column in the level image.
    pub x: u16,
    /// Row in the level image.
    pub y: u16,
    /// (Weighted) Harris response used for ranking.
    pub response: f32,
}

impl Candidate {
    /// An all-zero candidate (for `const` array initialisation).
    pub const ZERO: Candidate = Candidate { x: 0, y: 0, response: 0.0 };
}

/// A quadtree node: `[x0, x1) × [y0, y1)` and the candidates `start..end`.
#[derive(Clone, Copy, Debug)]
struct Node {
    x0: i32,
    y0: i32,
    x1: i32,
    y1: i32,
    start: u32,
    end: u32,
}

impl Node {
    const ZERO: Node = Node { x0: 0, y0: 0, x1: 0, y1: 0, start: 0, end: 0 };

    fn len(&self) -> usize {
        (self.end - self.start) as usize
    }
}

/// What a [`QuadTree::distribute`] call did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DistributeOutcome {
    /// Leaf nodes at the end (= key points returned).
    pub nodes: usize,
    /// True when node storage ran out and splitting stopped early.
    pub node_overflow: bool,
}

/// Node storage for up to `CAP` nodes (`28·CAP` bytes).
#[derive(Clone, Debug)]
pub struct QuadTree<const CAP: usize> {
    nodes: [Node; CAP],
    len: usize,
    order: [u32; CAP],
}

impl<const CAP: usize> Default for QuadTree<CAP> {
    fn default() -> Self {
        Self::new()
    }
}

/// Moves the elements satisfying `pred` to the front; returns how many there are.
fn partition(s: &mut [Candidate], pred: impl Fn(&Candidate) -> bool) -> usize {
    let mut k = 0;
    for i in 0..s.len() {
        if pred(&s[i]) {
            s.swap(i, k);
            k += 1;
        }
    }
    k
}

/// Stably moves the elements satisfying `pred` to the front (in place, by rotations: n·log n
/// moves, one `pred` call per element); returns how many there are.
fn stable_partition(s: &mut [Candidate], pred: &impl Fn(&Candidate) -> bool) -> usize {
    /// Slices up to this long are split through a buffer on the stack.
    const LEAF: usize = 32;
    if s.len() <= LEAF {
        let mut rest = [Candidate::ZERO; LEAF];
        let (mut k, mut r) = (0, 0);
        for i in 0..s.len() {
            let c = s[i];
            if pred(&c) {
                s[k] = c;
                k += 1;
            } else {
                rest[r] = c;
                r += 1;
            }
        }
        s[k..].copy_from_slice(&rest[..r]);
        return k;
    }
    let m = s.len() / 2;
    let a = stable_partition(&mut s[..m], pred);
    let b = stable_partition(&mut s[m..], pred);
    // [T₁ F₁ | T₂ F₂] → [T₁ T₂ F₁ F₂]
    s[a..m + b].rotate_left(m - a);
    a + b
}

/// Stably orders `s`, whose elements all have `strip(c)` in `lo..hi`, by strip.
fn stable_split_by_strip(
    s: &mut [Candidate],
    lo: usize,
    hi: usize,
    strip: &impl Fn(&Candidate) -> usize,
) {
    if hi - lo <= 1 || s.len() <= 1 {
        return;
    }
    let mid = lo + (hi - lo) / 2;
    let k = stable_partition(s, &|c| strip(c) < mid);
    let (left, right) = s.split_at_mut(k);
    stable_split_by_strip(left, lo, mid, strip);
    stable_split_by_strip(right, mid, hi, strip);
}

impl<const CAP: usize> QuadTree<CAP> {
    /// Empty storage (`const`).
    pub const fn new() -> Self {
        Self { nodes: [Node::ZERO; CAP], len: 0, order: [0; CAP] }
    }

    /// Splits node `i` into its non-empty quadrants: the first replaces node `i`, the rest are
    /// appended. Returns how many children hold more than one candidate, or `None` when there is
    /// no room for the children (the node is left as it was).
    fn divide(&mut self, i: usize, cands: &mut [Candidate]) -> Option<usize> {
        if self.len + 3 > CAP {
            return None;
        }
        let n = self.nodes[i];
        // ORB-SLAM2: halfX = ceil((UR.x − UL.x) / 2).
        let mx = n.x0 + (n.x1 - n.x0 + 1) / 2;
        let my = n.y0 + (n.y1 - n.y0 + 1) / 2;
        let s = &mut cands[n.start as usize..n.end as usize];
        let top = partition(s, |c| i32::from(c.y) < my);
        let (t, b) = s.split_at_mut(top);
        let tl = partition(t, |c| i32::from(c.x) < mx);
        let bl = partition(b, |c| i32::from(c.x) < mx);
        let st = n.start;
        let bounds = [st, st + tl as u32, st + top as u32, st + (top + bl) as u32, n.end];
        let rects = [
            (n.x0, n.y0, mx, my),
            (mx, n.y0, n.x1, my),
            (n.x0, my, mx, n.y1),
            (mx, my, n.x1, n.y1),
        ];
        let mut first = true;
        let mut multi = 0;
        for q in 0..4 {
            let (start, end) = (bounds[q], bounds[q + 1]);
            if end == start {
                continue;
            }
            let (x0, y0, x1, y1) = rects[q];
            let child = Node { x0, y0, x1, y1, start, end };
            if end - start > 1 {
                multi += 1;
            }
            if first {
                self.nodes[i] = child;
                first = false;
            } else {
                self.nodes[self.len] = child;
                self.len += 1;
            }
        }
        Some(multi)
    }

    /// Distributes `cands` (level coordinates, inside `xs × ys`) and
    /// calls `emit` with the strongest candidate of each final node, at most `n + 3` of them
    /// (fewer when there are fewer candidates). `cands` is reordered.
    pub fn distribute(
        &mut self,
        cands: &mut [Candidate],
        xs: core::ops::Range<i32>,
        ys: core::ops::Range<i32>,
        n: usize,
        mut emit: impl FnMut(&Candidate),
    ) -> DistributeOutcome {
        let (min_x, max_x, min_y, max_y) = (xs.start, xs.end, ys.start, ys.end);
        self.len = 0;
        let mut out = DistributeOutcome::default();
        if cands.is_empty() || n == 0 || CAP == 0 {
            return out;
        }
        let (w, h) = ((max_x - min_x).max(1), (max_y - min_y).max(1));
        // ORB-SLAM2: nIni = round(w / h) strips of width hX.
        let n_ini = crate::math::roundf(w as f32 / h as f32).max(1.0) as usize;
        let n_ini = n_ini.min(CAP);
        let hx = w as f32 / n_ini as f32;
        let strip = |c: &Candidate| -> usize {
            (((i32::from(c.x) - min_x) as f32 / hx) as usize).min(n_ini - 1)
        };
        // Order by (strip, y, x). Non-maximum suppression hands the candidates over in raster
        // order, (y, x), unless the bounded store overflowed and was cut by strength; from
        // raster order, a stable split by strip gives the same order as the sort (the key is
        // unique) in linear comparisons instead of n·log n of them, each with two divisions.
        if cands.windows(2).all(|p| (p[0].y, p[0].x) < (p[1].y, p[1].x)) {
            stable_split_by_strip(cands, 0, n_ini, &strip);
        } else {
            cands.sort_unstable_by_key(|c| (strip(c), c.y, c.x));
        }
        // Node rectangles are relative to (min_x, min_y) as in ORB-SLAM2; shift candidates' keys
        // by comparing in absolute coordinates instead.
        let mut k = 0usize;
        for s in 0..n_ini {
            let start = k;
            while k < cands.len() && strip(&cands[k]) == s {
                k += 1;
            }
            if k > start {
                let x0 = min_x + (hx * s as f32) as i32;
                let x1 = min_x + (hx * (s + 1) as f32) as i32;
                self.nodes[self.len] =
                    Node { x0, y0: min_y, x1, y1: max_y, start: start as u32, end: k as u32 };
                self.len += 1;
            }
        }

        'outer: loop {
            let prev = self.len;
            let mut to_expand = 0;
            for i in 0..prev {
                if self.nodes[i].len() > 1 {
                    match self.divide(i, cands) {
                        Some(m) => to_expand += m,
                        None => {
                            out.node_overflow = true;
                            break 'outer;
                        }
                    }
                }
            }
            if self.len >= n || self.len == prev {
                break;
            }
            if self.len + 3 * to_expand > n {
                // Split the biggest nodes first and stop as soon as the quota is met.
                loop {
                    let prev = self.len;
                    let mut m = 0;
                    for i in 0..self.len {
                        if self.nodes[i].len() > 1 {
                            self.order[m] = i as u32;
                            m += 1;
                        }
                    }
                    let nodes = &self.nodes;
                    self.order[..m].sort_unstable_by_key(|&i| {
                        (core::cmp::Reverse(nodes[i as usize].len()), i)
                    });
                    for j in 0..m {
                        let i = self.order[j] as usize;
                        if self.divide(i, cands).is_none() {
                            out.node_overflow = true;
                            break 'outer;
                        }
                        if self.len >= n {
                            break;
                        }
                    }
                    if self.len >= n || self.len == prev {
                        break 'outer;
                    }
                }
            }
        }

        for node in &self.nodes[..self.len] {
            let s = &cands[node.start as usize..node.end as usize];
            let mut best = &s[0];
            for c in &s[1..] {
                if c.response > best.response {
                    best = c;
                }
            }
            emit(best);
        }
        out.nodes = self.len;
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid_cands(w: u16, h: u16, step: u16) -> Vec<Candidate> {
        let mut v = Vec::new();
        for y in (0..h).step_by(step as usize) {
            for x in (0..w).step_by(step as usize) {
                let r = ((x as u32 * 7919 + y as u32 * 104_729) % 1000) as f32;
                v.push(Candidate { x, y, response: r });
            }
        }
        v
    }

    #[test]
    fn returns_quota_or_all() {
        let mut qt = QuadTree::<512>::new();
        let mut c = grid_cands(400, 100, 2);
        let mut got = Vec::new();
        let o = qt.distribute(&mut c, 0..400, 0..100, 300, |k| got.push(*k));
        assert!(got.len() >= 300 && got.len() <= 303, "{}", got.len());
        assert_eq!(o.nodes, got.len());
        assert!(!o.node_overflow);
        // Fewer candidates than the quota: every candidate comes back.
        let mut c = grid_cands(40, 40, 10);
        let n = c.len();
        got.clear();
        qt.distribute(&mut c, 0..40, 0..40, 100, |k| got.push(*k));
        assert_eq!(got.len(), n);
    }

    #[test]
    fn keeps_best_per_node_and_spreads() {
        // A dense cluster in one corner plus a sparse grid: the cluster must not take the quota.
        let mut c = grid_cands(200, 200, 20);
        for y in 0..30u16 {
            for x in 0..30u16 {
                c.push(Candidate { x, y, response: 5000.0 + f32::from(x + y) });
            }
        }
        let mut qt = QuadTree::<256>::new();
        let mut got = Vec::new();
        qt.distribute(&mut c, 0..200, 0..200, 100, |k| got.push(*k));
        let in_cluster = got.iter().filter(|k| k.x < 30 && k.y < 30).count();
        assert!(in_cluster < got.len() / 2, "{in_cluster} of {}", got.len());
        assert!(got.iter().any(|k| k.x >= 100 && k.y >= 100));
    }

    #[test]
    fn raster_input_takes_the_split_and_matches_the_sort() {
        // Sparse random candidates in raster order (as non-maximum suppression emits them) go
        // through the linear split by strip; the same set in another order goes through the
        // sort. The reordered slices and the emitted key points must be identical, for one to
        // several strips (w / h from 0.2 to 13) and quotas below and above the candidate count.
        let mut rng = crate::testing::Rng::new(0x9d7e_e5a1);
        for (w, h) in [(40u16, 200u16), (300, 100), (1241, 376), (1300, 100), (97, 61)] {
            for density in [3usize, 20, 200] {
                let mut raster = Vec::new();
                for y in 0..h {
                    for x in 0..w {
                        if rng.below(1000) < density {
                            let response = rng.below(50) as f32; // ties on purpose
                            raster.push(Candidate { x, y, response });
                        }
                    }
                }
                let mut shuffled = raster.clone();
                shuffled.reverse();
                let n = raster.len();
                for quota in [1usize, n / 3 + 1, n + 10] {
                    let mut qt = QuadTree::<4096>::new();
                    let (mut a, mut b) = (raster.clone(), shuffled.clone());
                    let (mut got_a, mut got_b) = (Vec::new(), Vec::new());
                    let oa = qt.distribute(&mut a, 0..i32::from(w), 0..i32::from(h), quota, |k| {
                        got_a.push(*k)
                    });
                    let ob = qt.distribute(&mut b, 0..i32::from(w), 0..i32::from(h), quota, |k| {
                        got_b.push(*k)
                    });
                    assert_eq!(oa, ob, "{w}x{h} density {density} quota {quota}");
                    assert_eq!(got_a, got_b, "{w}x{h} density {density} quota {quota}");
                    assert_eq!(a, b, "{w}x{h} density {density} quota {quota}");
                }
            }
        }
    }

    #[test]
    fn stable_partition_keeps_order_within_each_side() {
        let mut rng = crate::testing::Rng::new(7);
        for len in [0usize, 1, 2, 3, 17, 64, 1000] {
            let v: Vec<Candidate> = (0..len)
                .map(|i| Candidate { x: i as u16, y: rng.below(5) as u16, response: 0.0 })
                .collect();
            let mut s = v.clone();
            let k = stable_partition(&mut s, &|c| c.y < 2);
            let want: Vec<Candidate> = v
                .iter()
                .filter(|c| c.y < 2)
                .chain(v.iter().filter(|c| c.y >= 2))
                .copied()
                .collect();
            assert_eq!(k, v.iter().filter(|c| c.y < 2).count());
            assert_eq!(s, want, "len {len}");
        }
    }

    #[test]
    fn overflow_is_reported_not_a_panic() {
        let mut qt = QuadTree::<8>::new();
        let mut c = grid_cands(100, 100, 3);
        let mut got = 0;
        let o = qt.distribute(&mut c, 0..100, 0..100, 50, |_| got += 1);
        assert!(o.node_overflow);
        assert!(got <= 8 && got > 0);
    }
}
