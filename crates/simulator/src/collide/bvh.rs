//! Axis-aligned bounding boxes and a linear bounding-volume hierarchy (LBVH).
//!
//! Construction follows Karras, "Maximizing Parallelism in the Construction of BVHs, Octrees,
//! and k-d Trees" (HPG 2012): primitives are sorted by the 63-bit Morton code of their box
//! centres (21 bits per axis, ties broken by primitive index so all keys are distinct), and every
//! internal node `i` of the binary radix tree over the sorted keys finds its own key range and
//! split independently (in parallel with rayon). The tree is then relabelled in depth-first
//! pre-order so that every parent precedes its children: [`Bvh::refit`] is a single reverse sweep
//! and traversals walk memory mostly forwards. Leaves hold exactly one primitive.
//!
//! Queries: [`Bvh::query`] (all primitives whose box overlaps a box), [`Bvh::query_ball`]
//! (boxes within a Euclidean distance of a point), [`Bvh::nearest`]
//! (branch-and-bound closest primitive under a caller-supplied distance), and simultaneous
//! descent of two subtrees for [`Bvh::self_pairs`] (pairs i < j within one tree) and
//! [`Bvh::pairs_with`] (pairs across two trees). The pair queries first expand the top of the
//! traversal breadth-first into a few thousand independent tasks, then run them with rayon and
//! concatenate the results in task order, so the output is deterministic.

use nalgebra::Vector3;
use rayon::prelude::*;

/// An axis-aligned box `[min, max]` (closed). The empty box has `min = +∞`, `max = −∞`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Aabb {
    /// Lower corner.
    pub min: Vector3<f64>,
    /// Upper corner.
    pub max: Vector3<f64>,
}

impl Default for Aabb {
    fn default() -> Self {
        Aabb::empty()
    }
}

impl Aabb {
    /// The empty box (the identity of [`Aabb::union`]); it overlaps nothing.
    pub fn empty() -> Aabb {
        Aabb {
            min: Vector3::repeat(f64::INFINITY),
            max: Vector3::repeat(f64::NEG_INFINITY),
        }
    }

    /// The degenerate box holding only `p`.
    pub fn from_point(p: &Vector3<f64>) -> Aabb {
        Aabb { min: *p, max: *p }
    }

    /// The smallest box holding all `points` (empty for no points).
    pub fn from_points<'a>(points: impl IntoIterator<Item = &'a Vector3<f64>>) -> Aabb {
        let mut b = Aabb::empty();
        for p in points {
            b.grow(p);
        }
        b
    }

    /// Whether the box holds no point.
    pub fn is_empty(&self) -> bool {
        self.min.x > self.max.x || self.min.y > self.max.y || self.min.z > self.max.z
    }

    /// Extends the box to hold `p`.
    pub fn grow(&mut self, p: &Vector3<f64>) {
        self.min = self.min.inf(p);
        self.max = self.max.sup(p);
    }

    /// The smallest box holding both boxes.
    pub fn union(&self, o: &Aabb) -> Aabb {
        Aabb {
            min: self.min.inf(&o.min),
            max: self.max.sup(&o.max),
        }
    }

    /// The box grown by `r` on every side (the Minkowski sum with the cube of half-side `r`).
    pub fn inflate(&self, r: f64) -> Aabb {
        let d = Vector3::repeat(r);
        Aabb {
            min: self.min - d,
            max: self.max + d,
        }
    }

    /// Whether the two closed boxes share a point (touching counts).
    #[inline]
    pub fn overlaps(&self, o: &Aabb) -> bool {
        self.min.x <= o.max.x
            && o.min.x <= self.max.x
            && self.min.y <= o.max.y
            && o.min.y <= self.max.y
            && self.min.z <= o.max.z
            && o.min.z <= self.max.z
    }

    /// The centre `(min + max) / 2`.
    pub fn center(&self) -> Vector3<f64> {
        (self.min + self.max) * 0.5
    }

    /// Squared Euclidean distance from `p` to the box (0 inside).
    #[inline]
    pub fn distance_sq(&self, p: &Vector3<f64>) -> f64 {
        let mut s = 0.0;
        for k in 0..3 {
            let d = (self.min[k] - p[k]).max(p[k] - self.max[k]).max(0.0);
            s += d * d;
        }
        s
    }

    /// Half the surface area's edge sum `dx + dy + dz` (a cheap size measure).
    fn half_perimeter(&self) -> f64 {
        let e = self.max - self.min;
        e.x + e.y + e.z
    }
}

/// Marks a leaf in [`Node::left`].
const LEAF: u32 = u32::MAX;

#[derive(Debug, Clone, Copy)]
struct Node {
    aabb: Aabb,
    /// Left child, or [`LEAF`].
    left: u32,
    /// Right child, or the primitive of a leaf.
    right: u32,
}

impl Node {
    #[inline]
    fn is_leaf(&self) -> bool {
        self.left == LEAF
    }
}

/// A bounding-volume hierarchy over primitives given by their boxes (one primitive per leaf).
/// The root is node 0; parents precede their children.
#[derive(Debug, Clone, Default)]
pub struct Bvh {
    nodes: Vec<Node>,
    n_prims: usize,
    scratch: Scratch,
}

/// Build buffers kept for [`Bvh::rebuild`].
#[derive(Debug, Clone, Default)]
struct Scratch {
    /// (Morton code, primitive), sorted.
    keys: Vec<(u64, u32)>,
    /// Karras children of the internal nodes.
    children: Vec<[u32; 2]>,
    /// Relabelling stack.
    stack: Vec<(u32, u32, bool)>,
}

/// Spreads the low 21 bits of `x` to every third bit.
fn split3(x: u64) -> u64 {
    let mut x = x & 0x1f_ffff;
    x = (x | (x << 32)) & 0x001f_0000_0000_ffff;
    x = (x | (x << 16)) & 0x001f_0000_ff00_00ff;
    x = (x | (x << 8)) & 0x100f_00f0_0f00_f00f;
    x = (x | (x << 4)) & 0x10c3_0c30_c30c_30c3;
    x = (x | (x << 2)) & 0x1249_2492_4924_9249;
    x
}

/// 63-bit Morton code of `p` in the cube `[lo, lo + extent]³`.
fn morton(p: &Vector3<f64>, lo: &Vector3<f64>, inv_extent: f64) -> u64 {
    const SCALE: f64 = ((1u64 << 21) - 1) as f64;
    // `as` saturates (NaN → 0), so bad input cannot panic.
    let q = |k: usize| (((p[k] - lo[k]) * inv_extent).clamp(0.0, 1.0) * SCALE) as u64;
    (split3(q(0)) << 2) | (split3(q(1)) << 1) | split3(q(2))
}

/// Length of the common prefix of keys `i` and `j` (index-augmented), −1 when `j` is out of range.
#[inline]
fn delta(codes: &[(u64, u32)], i: i64, j: i64) -> i32 {
    if j < 0 || j >= codes.len() as i64 {
        return -1;
    }
    let (a, b) = (codes[i as usize].0, codes[j as usize].0);
    if a != b {
        (a ^ b).leading_zeros() as i32
    } else {
        64 + ((i as u32) ^ (j as u32)).leading_zeros() as i32
    }
}

/// Children of internal node `i` of the radix tree over `codes` (Karras 2012, Fig. 4).
/// Internal node k is encoded as k, leaf k as `n − 1 + k`.
fn karras_children(codes: &[(u64, u32)], i: usize) -> [u32; 2] {
    let n = codes.len();
    let i = i as i64;
    let d: i64 = if delta(codes, i, i + 1) >= delta(codes, i, i - 1) {
        1
    } else {
        -1
    };
    let dmin = delta(codes, i, i - d);
    let mut lmax: i64 = 2;
    while delta(codes, i, i + lmax * d) > dmin {
        lmax *= 2;
    }
    let mut l: i64 = 0;
    let mut t = lmax / 2;
    while t >= 1 {
        if delta(codes, i, i + (l + t) * d) > dmin {
            l += t;
        }
        t /= 2;
    }
    let j = i + l * d;
    let dnode = delta(codes, i, j);
    let mut s: i64 = 0;
    let mut t = l;
    loop {
        t = (t + 1) / 2;
        if delta(codes, i, i + (s + t) * d) > dnode {
            s += t;
        }
        if t <= 1 {
            break;
        }
    }
    let gamma = i + s * d + d.min(0);
    let leaf0 = (n - 1) as i64;
    let left = if i.min(j) == gamma {
        leaf0 + gamma
    } else {
        gamma
    };
    let right = if i.max(j) == gamma + 1 {
        leaf0 + gamma + 1
    } else {
        gamma + 1
    };
    [left as u32, right as u32]
}

/// A unit of pair traversal.
#[derive(Debug, Clone, Copy)]
enum Task {
    /// All pairs within the subtree of a node (self queries only).
    Within(u32),
    /// All pairs between a node of the first tree and a node of the second.
    Between(u32, u32),
}

/// One traversal step: emits leaf pairs and pushes sub-tasks.
#[inline]
fn step(
    a: &[Node],
    b: &[Node],
    same: bool,
    task: Task,
    emit: &mut impl FnMut(u32, u32),
    push: &mut impl FnMut(Task),
) {
    match task {
        Task::Within(n) => {
            let nd = &a[n as usize];
            if !nd.is_leaf() {
                push(Task::Within(nd.left));
                push(Task::Within(nd.right));
                push(Task::Between(nd.left, nd.right));
            }
        }
        Task::Between(x, y) => {
            let (nx, ny) = (&a[x as usize], &b[y as usize]);
            if !nx.aabb.overlaps(&ny.aabb) {
                return;
            }
            let split_x = match (nx.is_leaf(), ny.is_leaf()) {
                (true, true) => {
                    let (i, j) = (nx.right, ny.right);
                    if same {
                        emit(i.min(j), i.max(j));
                    } else {
                        emit(i, j);
                    }
                    return;
                }
                (true, false) => false,
                (false, true) => true,
                (false, false) => nx.aabb.half_perimeter() >= ny.aabb.half_perimeter(),
            };
            if split_x {
                push(Task::Between(nx.left, y));
                push(Task::Between(nx.right, y));
            } else {
                push(Task::Between(x, ny.left));
                push(Task::Between(x, ny.right));
            }
        }
    }
}

/// Runs `task` to completion depth-first.
fn run_task(a: &[Node], b: &[Node], same: bool, task: Task, emit: &mut impl FnMut(u32, u32)) {
    let mut stack = Vec::with_capacity(128);
    stack.push(task);
    while let Some(t) = stack.pop() {
        step(a, b, same, t, emit, &mut |t| stack.push(t));
    }
}

impl Bvh {
    /// Builds the hierarchy over `prims` (primitive `i` has box `prims[i]`).
    pub fn build(prims: &[Aabb]) -> Bvh {
        let mut bvh = Bvh::default();
        bvh.rebuild(prims);
        bvh
    }

    /// Rebuilds the hierarchy over `prims` from scratch, reusing this one's allocations (fresh
    /// memory is costly to touch: on a VM, page faults can cost more than the build itself).
    pub fn rebuild(&mut self, prims: &[Aabb]) {
        let n = prims.len();
        self.nodes.clear();
        self.n_prims = n;
        if n == 0 {
            return;
        }
        assert!(
            n < u32::MAX as usize / 2,
            "too many primitives for a u32 BVH"
        );
        let centers = prims
            .par_iter()
            .map(|b| Aabb::from_point(&b.center()))
            .reduce(Aabb::empty, |a, b| a.union(&b));
        let ext = centers.max - centers.min;
        let extent = ext.x.max(ext.y).max(ext.z);
        let inv_extent = if extent.is_finite() && extent > 0.0 {
            1.0 / extent
        } else {
            0.0
        };
        let lo = if centers.min.iter().all(|v| v.is_finite()) {
            centers.min
        } else {
            Vector3::zeros()
        };
        let Scratch {
            keys,
            children,
            stack,
        } = &mut self.scratch;
        keys.clear();
        keys.par_extend(
            prims
                .par_iter()
                .enumerate()
                .map(|(i, b)| (morton(&b.center(), &lo, inv_extent), i as u32)),
        );
        keys.par_sort_unstable();
        children.clear();
        let sorted: &[(u64, u32)] = keys;
        children.par_extend(
            (0..n - 1)
                .into_par_iter()
                .map(|i| karras_children(sorted, i)),
        );

        // Relabel in depth-first pre-order (parents before children).
        let leaf0 = (n - 1) as u32;
        let nodes = &mut self.nodes;
        nodes.reserve(2 * n - 1);
        // (old id, new parent, is right child)
        stack.clear();
        stack.push((0, u32::MAX, false));
        while let Some((old, parent, is_right)) = stack.pop() {
            let new = nodes.len() as u32;
            if parent != u32::MAX {
                let p = &mut nodes[parent as usize];
                if is_right {
                    p.right = new;
                } else {
                    p.left = new;
                }
            }
            if n == 1 || old >= leaf0 {
                let k = if n == 1 { 0 } else { (old - leaf0) as usize };
                let prim = keys[k].1;
                nodes.push(Node {
                    aabb: prims[prim as usize],
                    left: LEAF,
                    right: prim,
                });
            } else {
                nodes.push(Node {
                    aabb: Aabb::empty(),
                    left: 0,
                    right: 0,
                });
                let [l, r] = children[old as usize];
                stack.push((r, new, true));
                stack.push((l, new, false));
            }
        }
        self.refit_internal();
    }

    /// Number of primitives.
    pub fn len(&self) -> usize {
        self.n_prims
    }

    /// Whether the hierarchy holds no primitive.
    pub fn is_empty(&self) -> bool {
        self.n_prims == 0
    }

    /// The box of the whole hierarchy (empty when it holds nothing).
    pub fn root_aabb(&self) -> Aabb {
        self.nodes.first().map_or_else(Aabb::empty, |n| n.aabb)
    }

    /// Depth of the tree (a single leaf has depth 1, an empty tree 0).
    pub fn depth(&self) -> usize {
        if self.nodes.is_empty() {
            return 0;
        }
        let mut depth = vec![0u32; self.nodes.len()];
        depth[0] = 1;
        let mut max = 1;
        for i in 0..self.nodes.len() {
            let nd = self.nodes[i];
            if !nd.is_leaf() {
                depth[nd.left as usize] = depth[i] + 1;
                depth[nd.right as usize] = depth[i] + 1;
                max = max.max(depth[i] + 1);
            }
        }
        max as usize
    }

    /// Recomputes internal boxes from the leaves (children follow parents in `nodes`).
    fn refit_internal(&mut self) {
        for i in (0..self.nodes.len()).rev() {
            let nd = self.nodes[i];
            if !nd.is_leaf() {
                let b = self.nodes[nd.left as usize]
                    .aabb
                    .union(&self.nodes[nd.right as usize].aabb);
                self.nodes[i].aabb = b;
            }
        }
    }

    /// Updates every box for moved primitives without changing the tree (one O(n) sweep). Tree
    /// quality degrades when primitives move far relative to each other: rebuild now and then.
    /// If the number of primitives changed, this rebuilds.
    pub fn refit(&mut self, prims: &[Aabb]) {
        if prims.len() != self.n_prims {
            self.rebuild(prims);
            return;
        }
        for nd in self.nodes.iter_mut() {
            if nd.is_leaf() {
                nd.aabb = prims[nd.right as usize];
            }
        }
        self.refit_internal();
    }

    /// Calls `f(i)` for every primitive whose box overlaps `aabb`.
    pub fn query(&self, aabb: &Aabb, mut f: impl FnMut(u32)) {
        if self.nodes.is_empty() {
            return;
        }
        let mut stack: Vec<u32> = Vec::with_capacity(64);
        stack.push(0);
        while let Some(i) = stack.pop() {
            let nd = &self.nodes[i as usize];
            if !nd.aabb.overlaps(aabb) {
                continue;
            }
            if nd.is_leaf() {
                f(nd.right);
            } else {
                stack.push(nd.right);
                stack.push(nd.left);
            }
        }
    }

    /// Calls `f(i)` for every primitive whose box is within Euclidean distance `r` of `p`
    /// (tighter than [`Bvh::query`] with a cube of half-side `r`).
    pub fn query_ball(&self, p: &Vector3<f64>, r: f64, mut f: impl FnMut(u32)) {
        if self.nodes.is_empty() {
            return;
        }
        let r2 = r * r;
        let mut stack: Vec<u32> = Vec::with_capacity(64);
        stack.push(0);
        while let Some(i) = stack.pop() {
            let nd = &self.nodes[i as usize];
            if nd.aabb.distance_sq(p) > r2 {
                continue;
            }
            if nd.is_leaf() {
                f(nd.right);
            } else {
                stack.push(nd.right);
                stack.push(nd.left);
            }
        }
    }

    /// The primitive closest to `p` under `dist` (the true distance from `p` to primitive `i`,
    /// which must be at least the distance from `p` to the primitive's box), if any lies within
    /// `max_dist`; returns it and its distance. Branch and bound, nearer child first.
    pub fn nearest(
        &self,
        p: &Vector3<f64>,
        max_dist: f64,
        mut dist: impl FnMut(u32) -> f64,
    ) -> Option<(u32, f64)> {
        if self.nodes.is_empty() || max_dist.is_nan() || max_dist < 0.0 {
            return None;
        }
        let mut best = max_dist;
        let mut found: Option<u32> = None;
        let mut stack: Vec<(u32, f64)> = Vec::with_capacity(64);
        stack.push((0, self.nodes[0].aabb.distance_sq(p)));
        while let Some((i, d2)) = stack.pop() {
            if d2 > best * best {
                continue;
            }
            let nd = &self.nodes[i as usize];
            if nd.is_leaf() {
                let d = dist(nd.right);
                if d < best || (found.is_none() && d <= best) {
                    best = d;
                    found = Some(nd.right);
                }
                continue;
            }
            let dl = self.nodes[nd.left as usize].aabb.distance_sq(p);
            let dr = self.nodes[nd.right as usize].aabb.distance_sq(p);
            if dl <= dr {
                stack.push((nd.right, dr));
                stack.push((nd.left, dl));
            } else {
                stack.push((nd.left, dl));
                stack.push((nd.right, dr));
            }
        }
        found.map(|i| (i, best))
    }

    /// Calls `f(i, j)` (i < j) for every pair of distinct primitives whose boxes overlap
    /// (serial).
    pub fn for_each_self_pair(&self, mut f: impl FnMut(u32, u32)) {
        if self.nodes.is_empty() {
            return;
        }
        run_task(&self.nodes, &self.nodes, true, Task::Within(0), &mut f);
    }

    /// Calls `f(i, j)` for every primitive `i` of `self` and `j` of `other` whose boxes overlap
    /// (serial).
    pub fn for_each_pair_with(&self, other: &Bvh, mut f: impl FnMut(u32, u32)) {
        if self.nodes.is_empty() || other.nodes.is_empty() {
            return;
        }
        run_task(
            &self.nodes,
            &other.nodes,
            false,
            Task::Between(0, 0),
            &mut f,
        );
    }

    /// All pairs (i, j), i < j, of distinct primitives whose boxes overlap (parallel).
    pub fn self_pairs(&self) -> Vec<(u32, u32)> {
        self.self_pairs_filter_map(|i, j| Some((i, j)))
    }

    /// All pairs (i of `self`, j of `other`) whose boxes overlap (parallel).
    pub fn pairs_with(&self, other: &Bvh) -> Vec<(u32, u32)> {
        self.pairs_with_filter_map(other, |i, j| Some((i, j)))
    }

    /// `f(i, j)` over the overlapping pairs of [`Bvh::self_pairs`], keeping the `Some`s; `f`
    /// runs in parallel. The order is deterministic.
    pub fn self_pairs_filter_map<T: Send>(
        &self,
        f: impl Fn(u32, u32) -> Option<T> + Sync,
    ) -> Vec<T> {
        if self.nodes.is_empty() {
            return Vec::new();
        }
        par_traverse(&self.nodes, &self.nodes, true, Task::Within(0), &f)
    }

    /// `f(i, j)` over the overlapping pairs of [`Bvh::pairs_with`], keeping the `Some`s; `f`
    /// runs in parallel. The order is deterministic.
    pub fn pairs_with_filter_map<T: Send>(
        &self,
        other: &Bvh,
        f: impl Fn(u32, u32) -> Option<T> + Sync,
    ) -> Vec<T> {
        if self.nodes.is_empty() || other.nodes.is_empty() {
            return Vec::new();
        }
        par_traverse(&self.nodes, &other.nodes, false, Task::Between(0, 0), &f)
    }
}

/// Expands the traversal breadth-first into enough tasks, then runs them in parallel.
fn par_traverse<T: Send>(
    a: &[Node],
    b: &[Node],
    same: bool,
    start: Task,
    f: &(impl Fn(u32, u32) -> Option<T> + Sync),
) -> Vec<T> {
    // A fixed task count, not one per thread: the pairs found while expanding come first in
    // the output, so the order (and with it every later sum over contacts) would otherwise
    // depend on the thread count.
    let target = 1024;
    let mut out: Vec<T> = Vec::new();
    let mut tasks = vec![start];
    while !tasks.is_empty() && tasks.len() < target {
        let mut next = Vec::with_capacity(tasks.len() * 3);
        for t in tasks {
            step(a, b, same, t, &mut |i, j| out.extend(f(i, j)), &mut |t| {
                next.push(t)
            });
        }
        tasks = next;
    }
    let parts: Vec<Vec<T>> = tasks
        .par_iter()
        .map(|&t| {
            let mut v = Vec::new();
            run_task(a, b, same, t, &mut |i, j| v.extend(f(i, j)));
            v
        })
        .collect();
    out.reserve(parts.iter().map(Vec::len).sum());
    for p in parts {
        out.extend(p);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::BTreeSet;

    /// Tiny deterministic LCG in [0, 1).
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f64 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (self.0 >> 11) as f64 / (1u64 << 53) as f64
        }
        fn v3(&mut self, s: f64) -> Vector3<f64> {
            Vector3::new(self.next() * s, self.next() * s, self.next() * s)
        }
    }

    fn random_boxes(rng: &mut Lcg, n: usize, world: f64, size: f64) -> Vec<Aabb> {
        (0..n)
            .map(|_| {
                let c = rng.v3(world);
                let h = rng.v3(size);
                Aabb {
                    min: c - h,
                    max: c + h,
                }
            })
            .collect()
    }

    fn brute_self(b: &[Aabb]) -> BTreeSet<(u32, u32)> {
        let mut s = BTreeSet::new();
        for i in 0..b.len() {
            for j in i + 1..b.len() {
                if b[i].overlaps(&b[j]) {
                    s.insert((i as u32, j as u32));
                }
            }
        }
        s
    }

    fn brute_cross(a: &[Aabb], b: &[Aabb]) -> BTreeSet<(u32, u32)> {
        let mut s = BTreeSet::new();
        for (i, ba) in a.iter().enumerate() {
            for (j, bb) in b.iter().enumerate() {
                if ba.overlaps(bb) {
                    s.insert((i as u32, j as u32));
                }
            }
        }
        s
    }

    fn as_set(v: &[(u32, u32)]) -> BTreeSet<(u32, u32)> {
        let s: BTreeSet<_> = v.iter().copied().collect();
        assert_eq!(s.len(), v.len(), "duplicate pairs reported");
        s
    }

    #[test]
    fn aabb_basics() {
        let a = Aabb::from_points(&[Vector3::new(0.0, 0.0, 0.0), Vector3::new(1.0, 2.0, 3.0)]);
        let b = Aabb::from_point(&Vector3::new(1.5, 1.0, 1.0));
        assert!(!a.overlaps(&b));
        assert!(a.inflate(0.5).overlaps(&b));
        assert!(!a.inflate(0.49).overlaps(&b));
        let u = a.union(&b);
        assert_eq!(u.max, Vector3::new(1.5, 2.0, 3.0));
        assert!(Aabb::empty().is_empty() && !Aabb::empty().overlaps(&a));
        assert!((a.distance_sq(&Vector3::new(2.0, 3.0, 3.0)) - 2.0).abs() < 1e-15);
    }

    #[test]
    fn self_pairs_match_brute_force() {
        let mut rng = Lcg(7);
        for &(n, size) in &[
            (0usize, 0.1),
            (1, 0.1),
            (2, 0.5),
            (3, 0.3),
            (257, 0.05),
            (1500, 0.03),
        ] {
            let boxes = random_boxes(&mut rng, n, 1.0, size);
            let bvh = Bvh::build(&boxes);
            let want = brute_self(&boxes);
            assert_eq!(as_set(&bvh.self_pairs()), want, "n = {n}");
            let mut serial = Vec::new();
            bvh.for_each_self_pair(|i, j| serial.push((i, j)));
            assert_eq!(as_set(&serial), want);
        }
    }

    #[test]
    fn duplicate_centres_and_flat_scenes() {
        // Many identical boxes (equal Morton codes) and a scene flat in z.
        let mut boxes = vec![
            Aabb {
                min: Vector3::new(0.0, 0.0, 0.0),
                max: Vector3::new(1.0, 1.0, 0.0),
            };
            40
        ];
        let mut rng = Lcg(3);
        for _ in 0..200 {
            let c = Vector3::new(rng.next() * 3.0, rng.next() * 3.0, 0.0);
            boxes.push(Aabb::from_point(&c).inflate(0.05));
        }
        let bvh = Bvh::build(&boxes);
        assert_eq!(as_set(&bvh.self_pairs()), brute_self(&boxes));
        assert!(bvh.depth() < 80);
    }

    #[test]
    fn pairs_with_and_query_match_brute_force() {
        let mut rng = Lcg(11);
        let a = random_boxes(&mut rng, 700, 1.0, 0.04);
        let b = random_boxes(&mut rng, 450, 1.0, 0.06);
        let (ta, tb) = (Bvh::build(&a), Bvh::build(&b));
        let want = brute_cross(&a, &b);
        assert_eq!(as_set(&ta.pairs_with(&tb)), want);
        let mut serial = Vec::new();
        ta.for_each_pair_with(&tb, |i, j| serial.push((i, j)));
        assert_eq!(as_set(&serial), want);
        assert!(ta.pairs_with(&Bvh::build(&[])).is_empty());

        for _ in 0..30 {
            let (p, r) = (rng.v3(1.0), 0.1 * rng.next());
            let mut got = BTreeSet::new();
            ta.query_ball(&p, r, |i| {
                got.insert(i);
            });
            let want: BTreeSet<u32> = (0..a.len() as u32)
                .filter(|&i| a[i as usize].distance_sq(&p) <= r * r)
                .collect();
            assert_eq!(got, want);
        }
        for q in random_boxes(&mut rng, 30, 1.0, 0.2) {
            let mut got = BTreeSet::new();
            ta.query(&q, |i| {
                got.insert(i);
            });
            let want: BTreeSet<u32> = (0..a.len() as u32)
                .filter(|&i| a[i as usize].overlaps(&q))
                .collect();
            assert_eq!(got, want);
        }
    }

    #[test]
    fn refit_tracks_moved_boxes() {
        let mut rng = Lcg(5);
        let a = random_boxes(&mut rng, 600, 1.0, 0.04);
        let mut bvh = Bvh::build(&a);
        // Move everything (a shuffle-like permutation of positions): the tree is stale but valid.
        let moved: Vec<Aabb> = a
            .iter()
            .enumerate()
            .map(|(i, b)| {
                let o = a[(i * 7919) % a.len()].center() - b.center();
                Aabb {
                    min: b.min + o,
                    max: b.max + o,
                }
            })
            .collect();
        bvh.refit(&moved);
        assert_eq!(as_set(&bvh.self_pairs()), brute_self(&moved));
        let all = moved.iter().fold(Aabb::empty(), |u, b| u.union(b));
        assert_eq!(bvh.root_aabb(), all);
        // Rebuilding in place over other sets (smaller, empty, larger) is a fresh build.
        for m in [100usize, 0, 900] {
            let b = random_boxes(&mut rng, m, 1.0, 0.04);
            bvh.rebuild(&b);
            assert_eq!(bvh.len(), m);
            assert_eq!(as_set(&bvh.self_pairs()), brute_self(&b));
        }
        let more = random_boxes(&mut rng, 300, 1.0, 0.04);
        bvh.refit(&more); // a different count rebuilds
        assert_eq!(as_set(&bvh.self_pairs()), brute_self(&more));
    }

    #[test]
    fn nearest_matches_brute_force() {
        let mut rng = Lcg(13);
        let pts: Vec<Vector3<f64>> = (0..500).map(|_| rng.v3(1.0)).collect();
        let boxes: Vec<Aabb> = pts.iter().map(Aabb::from_point).collect();
        let bvh = Bvh::build(&boxes);
        for _ in 0..50 {
            let q = rng.v3(1.2) - Vector3::repeat(0.1);
            let got = bvh.nearest(&q, 0.2, |i| (pts[i as usize] - q).norm());
            let best = (0..pts.len())
                .map(|i| (i as u32, (pts[i] - q).norm()))
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .filter(|b| b.1 <= 0.2);
            assert_eq!(got.map(|g| g.0), best.map(|b| b.0));
        }
    }

    /// Build / refit / query timings on an ~80K-triangle grid (print only; run with
    /// `--release -- --nocapture bvh_timing`).
    #[test]
    fn bvh_timing_80k_triangles() {
        let m = 200usize;
        let pts: Vec<Vector3<f64>> = (0..=m)
            .flat_map(|i| {
                (0..=m).map(move |j| {
                    let (u, v) = (i as f64 / m as f64, j as f64 / m as f64);
                    Vector3::new(u, v, 0.05 * (6.0 * u).sin() * (5.0 * v).cos())
                })
            })
            .collect();
        let id = |i: usize, j: usize| (i * (m + 1) + j) as u32;
        let mut tris = Vec::new();
        for i in 0..m {
            for j in 0..m {
                tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        let boxes: Vec<Aabb> = tris
            .iter()
            .map(|t| Aabb::from_points(t.iter().map(|&k| &pts[k as usize])).inflate(1e-3))
            .collect();
        // Cold build, then the best of three rebuilds (warm rayon pool, reused memory).
        let t0 = std::time::Instant::now();
        let mut bvh = Bvh::build(&boxes);
        let t_cold = t0.elapsed();
        let mut t_build = std::time::Duration::MAX;
        for _ in 0..3 {
            let t0 = std::time::Instant::now();
            bvh.rebuild(&boxes);
            t_build = t_build.min(t0.elapsed());
        }
        let t0 = std::time::Instant::now();
        bvh.refit(&boxes);
        let t_refit = t0.elapsed();
        let t0 = std::time::Instant::now();
        let pairs = bvh.self_pairs();
        let t_self = t0.elapsed();
        let t0 = std::time::Instant::now();
        let mut hits = 0usize;
        for p in pts.iter() {
            bvh.query(&Aabb::from_point(p).inflate(1e-3), |_| hits += 1);
        }
        let t_query = t0.elapsed();
        println!(
            "BVH {} tris (depth {}): cold build {:?}, rebuild {:?}, refit {:?}, self_pairs {:?} ({} pairs), {} point queries {:?} ({} hits), {} threads",
            tris.len(),
            bvh.depth(),
            t_cold,
            t_build,
            t_refit,
            t_self,
            pairs.len(),
            pts.len(),
            t_query,
            hits,
            rayon::current_num_threads()
        );
        assert_eq!(bvh.len(), tris.len());
        // Each triangle touches its (up to 12) vertex neighbours at least.
        assert!(pairs.len() > 5 * tris.len());
    }
}
