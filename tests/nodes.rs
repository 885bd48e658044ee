//! The control-node field (docs/nodes.md): KNN on the GPU against the brute-force twin (ties,
//! fewer nodes than K, a split model), the blend forward, its backward and the per-node
//! gather against the twin (dense and through the dynamic rows), and the extremes: a Gaussian
//! far from every node, a tiny radius, coincident nodes, a NaN mean. The twin itself is
//! checked against central finite differences in `reference::nodes`.

use dispflow_vk::kernels::nodes::{
    key_bits, Access, BlendInputs, GatherShape, NodeKernels, SlotLoop, CONTRIB_STORED, NO_NODE,
};
use dispflow_vk::kernels::radix_sort::passes;
use dispflow_vk::kernels::shape::DeviceShape;
use dispflow_vk::reference::nodes::{nodes_gather, nodes_knn, nodes_lbs, nodes_lbs_bwd, Slot};
use dispflow_vk::testing::{self, assert_close, Noise, Tol};
use dispflow_vk::vk::{Buffer, Recorder};

fn rows3(v: &[f32]) -> Vec<[f32; 3]> {
    v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

/// A random problem: N Gaussians, M nodes with log-radii near ln 0.4 and non-identity node
/// transforms.
struct Problem {
    means: Vec<f32>,
    quats: Vec<f32>,
    /// [4M]: positions then log-radii.
    nodes: Vec<f32>,
    /// [M,10]
    node_out: Vec<f32>,
    m: usize,
}

fn problem(seed: u64, n: usize, m: usize) -> Problem {
    let mut r = Noise::new(seed);
    let means = r.uniforms(3 * n, -1.0, 1.0);
    let quats = r.uniforms(4 * n, -1.0, 1.0);
    let mut nodes = r.uniforms(3 * m, -1.0, 1.0);
    nodes.extend(r.uniforms(m, -1.3, -0.5));
    let mut node_out = Vec::new();
    for _ in 0..m {
        node_out.extend(r.uniforms(3, -0.2, 0.2)); // T
        node_out.extend(r.uniforms(4, -0.3, 0.3)); // dq
        node_out.extend(r.uniforms(3, -0.1, 0.1)); // ds
    }
    Problem {
        means,
        quats,
        nodes,
        node_out,
        m,
    }
}

impl Problem {
    fn n(&self) -> usize {
        self.means.len() / 3
    }

    /// The twin's slots of Gaussian `i` from KNN row `knn`.
    fn slots(&self, knn: &[u32]) -> Vec<Slot> {
        let m = self.m;
        knn.iter()
            .take_while(|&&j| j != NO_NODE)
            .map(|&j| {
                let j = j as usize;
                let f = |a: usize| self.nodes[a] as f64;
                Slot {
                    p: [f(3 * j), f(3 * j + 1), f(3 * j + 2)],
                    rho: f(3 * m + j),
                    out: std::array::from_fn(|c| self.node_out[10 * j + c] as f64),
                }
            })
            .collect()
    }

    fn mu(&self, i: usize) -> [f64; 3] {
        std::array::from_fn(|a| self.means[3 * i + a] as f64)
    }

    fn q(&self, i: usize) -> [f64; 4] {
        std::array::from_fn(|a| self.quats[4 * i + a] as f64)
    }
}

struct Gpu3 {
    gpu: testing::TestGpu,
    k: NodeKernels,
}

impl Gpu3 {
    fn new() -> Self {
        let gpu = testing::gpu();
        let k = NodeKernels::new(&gpu).unwrap();
        Gpu3 { gpu, k }
    }

    fn with_gather(shape: GatherShape) -> Self {
        let gpu = testing::gpu();
        let k = NodeKernels::with_gather(&gpu, shape).unwrap();
        Gpu3 { gpu, k }
    }

    fn with_shapes(shape: GatherShape, slots: SlotLoop, access: Access) -> Self {
        let gpu = testing::gpu();
        let k = NodeKernels::with_access(&gpu, shape, slots, access).unwrap();
        Gpu3 { gpu, k }
    }

    fn for_capacity(capacity: u32) -> Self {
        let gpu = testing::gpu();
        let k = NodeKernels::for_capacity(&gpu, capacity).unwrap();
        Gpu3 { gpu, k }
    }

    fn buf(&self, name: &str, v: &[f32]) -> Buffer {
        self.gpu.buffer_from(name, v).unwrap()
    }
}

/// The GPU KNN of `p` (optionally with a split `row_of`), checked against the twin, and the
/// sorted per-node ranges against a count. Returns the KNN.
fn knn_checked(g: &Gpu3, p: &Problem, k: u32, row_of: Option<&[u32]>) -> Vec<u32> {
    let n = p.n() as u32;
    let b = g.k.buffers(&g.gpu, n, p.m as u32, k).unwrap();
    let (means, nodes) = (g.buf("means", &p.means), g.buf("nodes", &p.nodes));
    let rows = row_of.map(|r| g.gpu.buffer_from("row_of", r).unwrap());
    let kb = g.gpu.buffer("knn", (n * k * 4) as u64).unwrap();
    let mut rec = Recorder::new(&g.gpu).unwrap();
    let m = p.m as u32;
    let ro = rows.as_ref().map(|r| r.all());
    g.k.record_knn(&mut rec, kb.all(), n, m, k, means.all(), nodes.all(), ro);
    g.k.record_pairs(&mut rec, &b, kb.all(), n, m);
    rec.finish().unwrap();
    let knn: Vec<u32> = g.gpu.read(kb.all()).unwrap();
    let active: Option<Vec<bool>> = row_of.map(|r| r.iter().map(|&v| v != NO_NODE).collect());
    let pos = rows3(&p.nodes[..3 * p.m]);
    let want = nodes_knn(&rows3(&p.means), &pos, k as usize, active.as_deref());
    assert_eq!(
        knn, want,
        "KNN: GPU vs brute-force twin (N {n}, M {m}, K {k})"
    );
    // Each node's range in the sorted pairs holds exactly its pairs, in pair order.
    let ranges: Vec<u32> = g.gpu.read(b.ranges.elems::<u32>(0, 2 * m as u64)).unwrap();
    let sorted = (passes(key_bits(m)) % 2) as usize;
    let vals: Vec<u32> = g
        .gpu
        .read(b.sort.vals[sorted].elems::<u32>(0, (n * k) as u64))
        .unwrap();
    for j in 0..m {
        let (s, e) = (ranges[2 * j as usize], ranges[2 * j as usize + 1]);
        let got = &vals[s as usize..e as usize];
        let want: Vec<u32> = (0..n * k).filter(|&q| knn[q as usize] == j).collect();
        assert_eq!(got, &want[..], "node {j}'s pairs");
    }
    knn
}

#[test]
fn knn_matches_brute_force_with_ties_few_nodes_and_a_split() {
    let g = Gpu3::new();
    let p = problem(1, 300, 37);
    knn_checked(&g, &p, 4, None);
    knn_checked(&g, &p, 8, None);
    // Fewer nodes than K: the tail is NO_NODE.
    let few = problem(2, 50, 3);
    let knn = knn_checked(&g, &few, 4, None);
    assert!(knn.chunks(4).all(|r| r[3] == NO_NODE && r[2] != NO_NODE));
    // Ties: nodes on the axes at distance 1 from a Gaussian at the origin — lower index first.
    let mut tie = problem(3, 1, 6);
    tie.means = vec![0.0; 3];
    tie.nodes[..18].copy_from_slice(&[
        0.0, 0.0, -1.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, -1.0, 0.0,
    ]);
    let knn = knn_checked(&g, &tie, 4, None);
    assert_eq!(knn, vec![0, 1, 2, 3]);
    // Split: a static Gaussian gets no node, and no pair in any node's list.
    let row_of: Vec<u32> = (0..300u32)
        .map(|i| if i % 3 == 0 { NO_NODE } else { i })
        .collect();
    let knn = knn_checked(&g, &p, 4, Some(&row_of));
    assert!(knn[..4].iter().all(|&j| j == NO_NODE) && knn[4] != NO_NODE);
}

/// Forward, backward and gather on the GPU against the twin; `split`: through the dynamic
/// rows (every third Gaussian static).
fn blend_checked(p: &Problem, k: u32, split: bool, tol: f64, gather: GatherShape) {
    blend_checked_on(&Gpu3::with_gather(gather), p, k, split, tol)
}

fn blend_checked_on(g: &Gpu3, p: &Problem, k: u32, split: bool, tol: f64) {
    // |gpu − twin| ≤ tol·(1 + |twin|)
    let tol = Tol::Elementwise { abs: tol, rel: tol };
    let n = p.n();
    let row_of: Vec<u32> = (0..n as u32)
        .map(|i| if split && i % 3 == 0 { NO_NODE } else { i })
        .collect();
    let knn = knn_checked(g, p, k, split.then_some(&row_of[..]));
    let idx: Vec<u32> = (0..n as u32)
        .filter(|&i| row_of[i as usize] != NO_NODE)
        .collect();
    let rows = if split { idx.len() } else { n };
    let mut r = Noise::new(9);
    let d_out = r.uniforms(10 * rows, -1.0, 1.0);
    let base_gm = r.uniforms(3 * n, -1.0, 1.0);
    let base_gq = r.uniforms(4 * n, -1.0, 1.0);
    let base_gn = r.uniforms(4 * p.m, -1.0, 1.0);

    let kk = &g.k;
    let b = kk.buffers(&g.gpu, n as u32, p.m as u32, k).unwrap();
    let bf = |name: &str, v: &[f32]| g.buf(name, v);
    let (means, quats, nodes, node_out) = (
        bf("means", &p.means),
        bf("quats", &p.quats),
        bf("nodes", &p.nodes),
        bf("node_out", &p.node_out),
    );
    let idx_b = g.gpu.buffer_from("idx", &idx).unwrap();
    let out = g.gpu.buffer("out", (rows * 40) as u64).unwrap();
    let (gd, gm, gq) = (bf("d_out", &d_out), bf("gm", &base_gm), bf("gq", &base_gq));
    let gn = bf("gn", &base_gn);
    let d_node = g.gpu.buffer("d_node_out", (p.m * 40) as u64).unwrap();
    let kb = g.gpu.buffer_from("knn", &knn).unwrap();
    let x = BlendInputs {
        m: p.m as u32,
        k,
        knn: kb.all(),
        means: means.all(),
        quats: quats.all(),
        nodes: nodes.all(),
        node_out: node_out.all(),
    };
    let ix = split.then(|| idx_b.all());
    let mut rec = Recorder::new(&g.gpu).unwrap();
    kk.record_pairs(&mut rec, &b, kb.all(), n as u32, p.m as u32);
    kk.record_lbs(&mut rec, rows as u32, &x, ix, out.all());
    kk.record_lbs_bwd(
        &mut rec,
        &b,
        rows as u32,
        &x,
        ix,
        gd.all(),
        gm.all(),
        gq.all(),
    );
    kk.record_gather(&mut rec, &b, p.m as u32, d_node.all(), gn.all(), true);
    rec.finish().unwrap();
    let rd = |b: &Buffer| g.gpu.read::<f32>(b.all()).unwrap();
    let (got_out, got_gm, got_gq) = (rd(&out), rd(&gm), rd(&gq));
    let (got_dn, got_gn) = (rd(&d_node), rd(&gn));
    let contrib = rd(&b.contrib);

    let ku = k as usize;
    let mut all_contrib = vec![[0f64; dispflow_vk::reference::nodes::CONTRIB]; n * ku];
    for (row, i) in (0..rows).map(|row| (row, if split { idx[row] as usize } else { row })) {
        let slots = p.slots(&knn[ku * i..ku * i + ku]);
        let want = nodes_lbs(p.mu(i), p.q(i), &slots);
        for c in 0..10 {
            assert_close(
                &format!("D[{i}][{c}]"),
                &[got_out[10 * row + c]],
                &[want[c]],
                tol,
            );
        }
        let up: [f64; 10] = std::array::from_fn(|c| d_out[10 * row + c] as f64);
        let (gmu, gqq, cs) = nodes_lbs_bwd(p.mu(i), p.q(i), &slots, up);
        for a in 0..3 {
            let w = base_gm[3 * i + a] as f64 + gmu[a];
            assert_close(
                &format!("dL/dmu[{i}][{a}] (added)"),
                &[got_gm[3 * i + a]],
                &[w],
                tol,
            );
        }
        for a in 0..4 {
            let w = base_gq[4 * i + a] as f64 + gqq[a];
            assert_close(
                &format!("dL/dq[{i}][{a}] (added)"),
                &[got_gq[4 * i + a]],
                &[w],
                tol,
            );
        }
        for (s, c) in cs.iter().enumerate() {
            all_contrib[ku * i + s] = *c;
            for (a, &want) in c.iter().enumerate() {
                let at = (ku * i + s) * CONTRIB_STORED as usize + a;
                assert_close(
                    &format!("contrib[{i}][{s}][{a}]"),
                    &[contrib[at]],
                    &[want],
                    tol,
                );
            }
        }
    }
    for (i, &r) in row_of.iter().enumerate() {
        if r == NO_NODE {
            // A static Gaussian: its canonical gradients are untouched.
            assert_eq!(got_gm[3 * i..3 * i + 3], base_gm[3 * i..3 * i + 3]);
        }
    }
    let (dn, gnodes) = nodes_gather(&knn, &all_contrib, p.m);
    for j in 0..p.m {
        for c in 0..10 {
            assert_close(
                &format!("dL/dnode_out[{j}][{c}]"),
                &[got_dn[10 * j + c]],
                &[dn[j][c]],
                tol,
            );
        }
        for a in 0..3 {
            let w = base_gn[3 * j + a] as f64 + gnodes[j][a];
            assert_close(
                &format!("dL/dp[{j}][{a}] (added)"),
                &[got_gn[3 * j + a]],
                &[w],
                tol,
            );
        }
        let w = base_gn[3 * p.m + j] as f64 + gnodes[j][3];
        assert_close(
            &format!("dL/drho[{j}] (added)"),
            &[got_gn[3 * p.m + j]],
            &[w],
            tol,
        );
    }
}

#[test]
fn blend_forward_backward_and_gather_match_the_twin() {
    // Both gather shapes (the tree GPUs run, the serial loop CPU devices run), both slot
    // loops (all 8 slots, as GPUs; 4 slots at K <= 4, as CPU devices) and, for the GPU's and
    // the CPU's pair, both array accesses (storage and texel buffers) against the twin.
    for shape in [GatherShape::Tree, GatherShape::Serial] {
        for slots in [SlotLoop::Max, SlotLoop::Fit] {
            let mut accesses = vec![Access::Buffer];
            if (shape, slots) == (GatherShape::Serial, SlotLoop::Fit) {
                accesses.push(Access::Texel);
            }
            if (shape, slots) == (GatherShape::Tree, SlotLoop::Max) {
                accesses.push(Access::Texel);
            }
            for access in accesses {
                let g = Gpu3::with_shapes(shape, slots, access);
                blend_checked_on(&g, &problem(4, 200, 23), 4, false, 2e-4);
                blend_checked_on(&g, &problem(5, 120, 9), 1, false, 2e-4);
                blend_checked_on(&g, &problem(6, 150, 17), 8, true, 2e-4);
            }
        }
    }
}

#[test]
fn extremes_stay_finite() {
    // Gaussian 0 is 1e3 from every node with a tiny radius; nodes 0 and 1 coincide; node 2's
    // log-radius is far below the clamp; Gaussian 2's mean is NaN (no node: D = 0).
    let mut p = problem(7, 6, 5);
    p.means[..3].copy_from_slice(&[1e3, -1e3, 1e3]);
    let n0: Vec<f32> = p.nodes[..3].to_vec();
    p.nodes[3..6].copy_from_slice(&n0);
    p.nodes[3 * 5] = -30.0;
    p.nodes[3 * 5 + 2] = -30.0;
    p.nodes[3 * 5 + 4] = 30.0;
    for shape in [GatherShape::Tree, GatherShape::Serial] {
        blend_checked(&p, 4, false, 2e-4, shape);
    }
    p.means[6..9].copy_from_slice(&[f32::NAN; 3]);
    let g = Gpu3::new();
    let kb = g.gpu.buffer("knn", 6 * 4 * 4).unwrap();
    let (means, quats, nodes, node_out) = (
        g.buf("means", &p.means),
        g.buf("quats", &p.quats),
        g.buf("nodes", &p.nodes),
        g.buf("node_out", &p.node_out),
    );
    let out = g.gpu.buffer("out", 6 * 40).unwrap();
    let x = BlendInputs {
        m: 5,
        k: 4,
        knn: kb.all(),
        means: means.all(),
        quats: quats.all(),
        nodes: nodes.all(),
        node_out: node_out.all(),
    };
    let mut rec = Recorder::new(&g.gpu).unwrap();
    g.k.record_knn(&mut rec, kb.all(), 6, 5, 4, means.all(), nodes.all(), None);
    g.k.record_lbs(&mut rec, 6, &x, None, out.all());
    rec.finish().unwrap();
    let d: Vec<f32> = g.gpu.read(out.all()).unwrap();
    assert!(d.iter().all(|v| v.is_finite()), "{d:?}");
    assert!(
        d[20..30].iter().all(|&v| v == 0.0),
        "a NaN mean has no node: D = 0"
    );
}
dispflow_vk::subgroup_reruns!();

/// A node shared by 70 000 Gaussians: on lavapipe the `serial` gather (one invocation per node)
/// would be cut at 65 535 pairs (measured: dL/dnode_out 190.6 against the twin's 218.1), so the
/// kernels for a model that large run the tree there; below the limit they keep the device's
/// shape. Fails with `for_capacity` choosing by the device alone.
#[test]
fn a_node_shared_by_more_gaussians_than_a_loop_may_run_gathers_them_all() {
    use dispflow_vk::kernels::nodes::SERIAL_GATHER_MAX;
    let n = 70_000;
    let g = Gpu3::for_capacity(n as u32);
    let device = GatherShape::for_device(&g.gpu.info);
    if device == GatherShape::Serial {
        assert_eq!(g.k.gather_shape(), GatherShape::Tree);
    }
    blend_checked_on(&g, &problem(8, n, 1), 1, false, 2e-4);
    let small = NodeKernels::for_capacity(&g.gpu, SERIAL_GATHER_MAX).unwrap();
    assert_eq!(small.gather_shape(), device);
}
