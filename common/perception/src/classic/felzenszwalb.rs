//! Felzenszwalb–Huttenlocher merging over sorted edges.

use super::graph::Edge;
use super::union_find::UnionFind;

/// Merges components in edge order while the edge weight stays within
/// Int(C) + k/|C| of both sides, then absorbs components under `min_size`.
pub fn segment_graph(
    sorted: &[Edge],
    vertices: usize,
    k: f32,
    min_size: u32,
    sets: &mut UnionFind,
) {
    sets.reset(vertices, k);
    for e in sorted {
        let (ra, rb) = (sets.find(e.a), sets.find(e.b));
        if ra == rb {
            continue;
        }
        let w = e.weight();
        if w <= sets.threshold(ra) && w <= sets.threshold(rb) {
            let root = sets.union(ra, rb);
            // Edges arrive in increasing order, so w is the new Int(C).
            sets.set_threshold(root, w + k / sets.size(root) as f32);
        }
    }
    // Cheapest edges first, so small fragments join their most similar neighbour.
    for e in sorted {
        let (ra, rb) = (sets.find(e.a), sets.find(e.b));
        if ra != rb && (sets.size(ra) < min_size || sets.size(rb) < min_size) {
            sets.union(ra, rb);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classic::graph::BIN_WIDTH;

    fn edge(a: u32, b: u32, w: f32) -> Edge {
        Edge {
            a,
            b,
            bin: (w / BIN_WIDTH).round() as u16,
        }
    }

    #[test]
    fn separates_two_cliques_by_a_strong_edge() {
        // Chain 0-1-2 | 3-4-5 with a heavy edge between 2 and 3.
        let mut edges = vec![
            edge(0, 1, 0.01),
            edge(1, 2, 0.01),
            edge(3, 4, 0.01),
            edge(4, 5, 0.01),
            edge(2, 3, 2.0),
        ];
        edges.sort_by_key(|e| e.bin);
        let mut uf = UnionFind::default();
        segment_graph(&edges, 6, 0.5, 1, &mut uf);
        assert_eq!(uf.find(0), uf.find(2));
        assert_eq!(uf.find(3), uf.find(5));
        assert_ne!(uf.find(0), uf.find(3));
        // A minimum size of 4 forces the merge.
        segment_graph(&edges, 6, 0.5, 4, &mut uf);
        assert_eq!(uf.find(0), uf.find(5));
    }
}
