//! OctoMap's binary scan-graph files (`.graph`), read and written.
//!
//! A scan graph is what OctoMap's `log2graph` writes and `graph2tree` turns into a map: a list
//! of nodes (a point cloud in the sensor frame, the sensor pose, an id) and a list of edges
//! (relative-pose constraints between nodes, for SLAM back-ends; `graph2tree` ignores them).
//!
//! # Layout
//!
//! Everything little-endian, no header, no padding, as `ScanGraph::writeBinary` writes it:
//!
//! ```text
//! u32 node count
//! per node:
//!     u32 point count n
//!     n x point:  i32 3, f64 x, f64 y, f64 z                       (28 bytes)
//!     pose:       i32 3, f64 tx, f64 ty, f64 tz                    (28 bytes)
//!                 i32 4, f64 qw, f64 qx, f64 qy, f64 qz            (36 bytes)
//!     u32 id
//! u32 edge count
//! per edge:
//!     u32 first id, u32 second id
//!     pose (the constraint, same two records as above)
//!     f64 weight
//! ```
//!
//! The leading `i32` of each vector and quaternion record is the number of values that follow
//! (3 or 4). OctoMap writes it but does not check it when reading, so neither does [`read`]:
//! any value is accepted and dropped, and [`write`] always writes 3 and 4.
//!
//! OctoMap reads every coordinate and quaternion component into `f32` with a plain C cast
//! (`(float) val`): round to nearest, magnitudes beyond `f32::MAX` become infinities. [`read`]
//! does exactly that (`v as f32`), so the scans it returns are the ones OctoMap inserts, bit for
//! bit. Writing widens `f32` to `f64`, which is exact: a written graph reads back to the same
//! `f32` values. The edge weight is a `f64` in OctoMap too and is kept as read.
//!
//! Point clouds in this format carry no colour: read scans have `colors: None`, and colours of
//! written scans are dropped.
//!
//! # No-panic contract
//!
//! [`read`] and [`read_scans`] take untrusted bytes and never panic, on any input. Every failure
//! is a [`ParseError`] whose offset is the byte where the record that could not be read starts,
//! and whose message names the record, e.g. `offset 1234: node 3 of 5, point 17 of 10201:
//! expected 28 bytes, 5 left` (node, point and edge numbers count from 1). Allocation is capped
//! by the bytes actually present: a count claiming four billion points in a 100-byte file fails
//! at the first missing point without reserving memory for the claim.
//!
//! What is an error: any record cut short (including a file that ends before the edge count,
//! which OctoMap would silently read as zero edges), and bytes left over after the last edge
//! (OctoMap ignores them; here they most likely mean a corrupted or concatenated file). What is
//! not: unchecked record tags (above), edges naming ids no node has (OctoMap prints an error and
//! keeps reading), duplicate node ids, and non-finite or non-unit values (OctoMap takes them).

use super::{ParseError, Pose, Scan};

/// Bytes of one point (or translation) record: `i32` tag and three `f64`.
pub const VECTOR_RECORD_BYTES: usize = 4 + 3 * 8;
/// Bytes of one quaternion record: `i32` tag and four `f64`.
pub const QUATERNION_RECORD_BYTES: usize = 4 + 4 * 8;
/// Bytes of a pose: a translation record and a quaternion record.
pub const POSE_BYTES: usize = VECTOR_RECORD_BYTES + QUATERNION_RECORD_BYTES;
/// Bytes of a node without points: point count, pose, id.
pub const EMPTY_NODE_BYTES: usize = 4 + POSE_BYTES + 4;
/// Bytes of one edge: two ids, the constraint pose, the weight.
pub const EDGE_BYTES: usize = 4 + 4 + POSE_BYTES + 8;

/// The tag OctoMap writes before a vector record (its number of values).
const VECTOR_TAG: i32 = 3;
/// The tag OctoMap writes before a quaternion record.
const QUATERNION_TAG: i32 = 4;

/// A relative-pose constraint between two nodes of a scan graph.
///
/// Kept for completeness and round trips; building a map does not use edges.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Edge {
    /// Id of the first node (as stored; not checked against the nodes' ids).
    pub first_id: u32,
    /// Id of the second node (as stored; not checked against the nodes' ids).
    pub second_id: u32,
    /// Pose of the second node in the frame of the first (OctoMap: `first.inv() * second`).
    pub constraint: Pose,
    /// Weight of the constraint (OctoMap's default is 1.0).
    pub weight: f64,
}

/// A whole scan graph: nodes (as parallel `scans` and `ids`) and edges.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Graph {
    /// The nodes' scans, in file order; `colors` is always `None` when read.
    pub scans: Vec<Scan>,
    /// The nodes' ids, one per scan, in file order.
    pub ids: Vec<u32>,
    /// The edges, in file order.
    pub edges: Vec<Edge>,
}

impl Graph {
    /// The graph's `.graph` bytes: [`write_graph`].
    pub fn to_bytes(&self) -> Vec<u8> {
        write_graph(self)
    }
}

/// Reads a whole `.graph` file. Never panics; see the module docs for what is an error.
pub fn read(bytes: &[u8]) -> Result<Graph, ParseError> {
    let mut r = Reader { bytes, pos: 0 };

    let node_count = r.u32(|| "node count".to_string())?;
    let mut scans = Vec::with_capacity(capped(node_count, r.left(), EMPTY_NODE_BYTES));
    let mut ids = Vec::with_capacity(scans.capacity());
    for node in 1..=node_count {
        let (scan, id) = read_node(&mut r, node, node_count)?;
        scans.push(scan);
        ids.push(id);
    }
    let edges = read_edges(&mut r)?;
    Ok(Graph { scans, ids, edges })
}

/// Node `node` of `node_count`: its scan and id.
fn read_node<S: Source>(r: &mut S, node: u32, node_count: u32) -> Result<(Scan, u32), ParseError> {
    let at = |what: &str| format!("node {node} of {node_count}, {what}");
    let point_count = r.u32(|| at("point count"))?;
    let mut points = Vec::with_capacity(capped(point_count, r.left(), VECTOR_RECORD_BYTES));
    for point in 1..=point_count {
        points.push(r.vector(|| at(&format!("point {point} of {point_count}")))?);
    }
    let pose = r.pose(|what| at(&format!("pose {what}")))?;
    let id = r.u32(|| at("id"))?;
    Ok((
        Scan {
            points,
            colors: None,
            pose,
        },
        id,
    ))
}

/// The edge count and edges, then the end of the input.
fn read_edges<S: Source>(r: &mut S) -> Result<Vec<Edge>, ParseError> {
    let edge_count = r.u32(|| "edge count".to_string())?;
    let mut edges = Vec::with_capacity(capped(edge_count, r.left(), EDGE_BYTES));
    for edge in 1..=edge_count {
        let at = |what: &str| format!("edge {edge} of {edge_count}, {what}");
        let first_id = r.u32(|| at("first id"))?;
        let second_id = r.u32(|| at("second id"))?;
        let constraint = r.pose(|what| at(&format!("constraint {what}")))?;
        let weight = f64::from_le_bytes(r.array(|| at("weight"))?);
        edges.push(Edge {
            first_id,
            second_id,
            constraint,
            weight,
        });
    }
    if r.left() > 0 {
        return Err(ParseError::new(
            r.pos() as u64,
            format!("{} bytes after the last of {edge_count} edges", r.left()),
        ));
    }
    Ok(edges)
}

/// Scans read one at a time from a byte stream (a file), so a large graph never sits in memory
/// whole: the same checks and errors as [`read`], node by node; after the last node, the edges
/// are read, checked and dropped. The stream's length must be known (a file's size) for the
/// "bytes left" in errors and the cap on allocations.
pub struct ScanStream<R: std::io::Read> {
    src: StreamSource<R>,
    node: u32,
    node_count: u32,
    finished: bool,
}

impl<R: std::io::Read> ScanStream<R> {
    /// Starts reading a graph of `len` bytes from `reader` (its node count).
    pub fn new(reader: R, len: u64) -> Result<Self, ParseError> {
        let mut src = StreamSource {
            reader: std::io::BufReader::with_capacity(1 << 16, reader),
            pos: 0,
            len,
        };
        let node_count = src.u32(|| "node count".to_string())?;
        Ok(ScanStream {
            src,
            node: 0,
            node_count,
            finished: false,
        })
    }

    /// Nodes the graph says it has.
    pub fn node_count(&self) -> u32 {
        self.node_count
    }
}

impl<R: std::io::Read> Iterator for ScanStream<R> {
    type Item = Result<Scan, ParseError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.finished {
            return None;
        }
        if self.node == self.node_count {
            self.finished = true;
            return read_edges(&mut self.src).err().map(Err);
        }
        self.node += 1;
        match read_node(&mut self.src, self.node, self.node_count) {
            Ok((scan, _)) => Some(Ok(scan)),
            Err(e) => {
                self.finished = true;
                Some(Err(e))
            }
        }
    }
}

/// Reads the scans of a `.graph` file (its nodes, in file order), checking the whole file as
/// [`read`] does; ids and edges are dropped.
pub fn read_scans(bytes: &[u8]) -> Result<Vec<Scan>, ParseError> {
    read(bytes).map(|graph| graph.scans)
}

/// The `.graph` bytes of `scans` as nodes with ids `0..n` and **no edges** (what `graph2tree`
/// needs; it ignores edges). Colours are dropped: the format has none.
///
/// # Panics
///
/// If there are more than `u32::MAX` scans or a scan has more than `u32::MAX` points (the
/// format's counts are `u32`; such inputs would need tens of gigabytes of memory).
pub fn write(scans: &[Scan]) -> Vec<u8> {
    let mut out = Vec::with_capacity(nodes_bytes(scans) + 4);
    put_u32(&mut out, count(scans.len(), "scans"));
    for (id, scan) in scans.iter().enumerate() {
        put_node(&mut out, scan, count(id, "scans"));
    }
    put_u32(&mut out, 0);
    out
}

/// The bytes of one node of a `.graph` ([`write`]'s node `id`): what a recorder appends per
/// scan after the node count, before the edge count.
///
/// # Panics
///
/// If the scan has more than `u32::MAX` points.
pub fn node_bytes(scan: &Scan, id: u32) -> Vec<u8> {
    let mut out = Vec::new();
    put_node(&mut out, scan, id);
    out
}

/// The `.graph` bytes of a whole graph, edges included.
///
/// Node `i` gets id `graph.ids[i]`, or `i` when `ids` is shorter than `scans` (extra ids are
/// ignored). Reading the bytes back gives `graph` again, values bit for bit, except colours
/// (dropped: the format has none) and ids filled in as described.
///
/// # Panics
///
/// If a count (scans, points of a scan, edges) exceeds `u32::MAX`.
pub fn write_graph(graph: &Graph) -> Vec<u8> {
    let mut out =
        Vec::with_capacity(nodes_bytes(&graph.scans) + 4 + graph.edges.len() * EDGE_BYTES);
    put_u32(&mut out, count(graph.scans.len(), "scans"));
    for (i, scan) in graph.scans.iter().enumerate() {
        let id = graph
            .ids
            .get(i)
            .copied()
            .unwrap_or_else(|| count(i, "scans"));
        put_node(&mut out, scan, id);
    }
    put_u32(&mut out, count(graph.edges.len(), "edges"));
    for edge in &graph.edges {
        put_u32(&mut out, edge.first_id);
        put_u32(&mut out, edge.second_id);
        put_pose(&mut out, &edge.constraint);
        out.extend_from_slice(&edge.weight.to_le_bytes());
    }
    out
}

// ---- reading ------------------------------------------------------------------------------

/// How many items of `size` bytes to reserve for a claimed `claimed`: no more than fit in what
/// is left of the input.
fn capped(claimed: u32, left: usize, size: usize) -> usize {
    usize::try_from(claimed)
        .map_or(usize::MAX, |c| c)
        .min(left / size)
}

/// Where records come from: a byte slice or a stream of known length.
trait Source {
    /// Offset of the next byte.
    fn pos(&self) -> usize;
    /// Bytes left.
    fn left(&self) -> usize;
    /// The next `N` bytes, or an error at the current offset naming `what` (built only then).
    fn array<const N: usize>(
        &mut self,
        what: impl FnOnce() -> String,
    ) -> Result<[u8; N], ParseError>;

    fn u32(&mut self, what: impl FnOnce() -> String) -> Result<u32, ParseError> {
        self.array(what).map(u32::from_le_bytes)
    }

    /// A vector record: the tag (unchecked, as OctoMap) and three `f64` cast to `f32`.
    fn vector(&mut self, what: impl FnOnce() -> String) -> Result<[f32; 3], ParseError> {
        let b: [u8; VECTOR_RECORD_BYTES] = self.array(what)?;
        Ok([f64_at(&b, 4), f64_at(&b, 12), f64_at(&b, 20)])
    }

    /// A quaternion record: the tag (unchecked) and four `f64` (w, x, y, z) cast to `f32`.
    fn quaternion(&mut self, what: impl FnOnce() -> String) -> Result<[f32; 4], ParseError> {
        let b: [u8; QUATERNION_RECORD_BYTES] = self.array(what)?;
        Ok([
            f64_at(&b, 4),
            f64_at(&b, 12),
            f64_at(&b, 20),
            f64_at(&b, 28),
        ])
    }

    /// A pose; `what` gets "translation" or "rotation".
    fn pose(&mut self, what: impl Fn(&str) -> String) -> Result<Pose, ParseError> {
        let translation_m = self.vector(|| what("translation"))?;
        let rotation = self.quaternion(|| what("rotation"))?;
        Ok(Pose {
            translation_m,
            rotation,
        })
    }
}

/// A cursor over the input that names what it failed to read.
struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl Source for Reader<'_> {
    fn pos(&self) -> usize {
        self.pos
    }

    fn left(&self) -> usize {
        self.bytes.len() - self.pos
    }

    fn array<const N: usize>(
        &mut self,
        what: impl FnOnce() -> String,
    ) -> Result<[u8; N], ParseError> {
        let rest = &self.bytes[self.pos..];
        match rest.first_chunk::<N>() {
            Some(chunk) => {
                self.pos += N;
                Ok(*chunk)
            }
            None => Err(ParseError::new(
                self.pos as u64,
                format!("{}: expected {N} bytes, {} left", what(), rest.len()),
            )),
        }
    }
}

/// A buffered stream of known length.
struct StreamSource<R: std::io::Read> {
    reader: std::io::BufReader<R>,
    pos: usize,
    len: u64,
}

impl<R: std::io::Read> Source for StreamSource<R> {
    fn pos(&self) -> usize {
        self.pos
    }

    fn left(&self) -> usize {
        usize::try_from(self.len.saturating_sub(self.pos as u64)).unwrap_or(usize::MAX)
    }

    fn array<const N: usize>(
        &mut self,
        what: impl FnOnce() -> String,
    ) -> Result<[u8; N], ParseError> {
        use std::io::{BufRead, Read};
        // Most records are whole in the buffer: copied from it without a read call.
        if let Some(&chunk) = self.reader.buffer().first_chunk::<N>() {
            self.reader.consume(N);
            self.pos += N;
            return Ok(chunk);
        }
        let mut b = [0u8; N];
        let mut got = 0;
        while got < N {
            match self.reader.read(&mut b[got..]) {
                Ok(0) => break,
                Ok(n) => got += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => {
                    return Err(ParseError::new(
                        (self.pos + got) as u64,
                        format!("{}: read failed: {e}", what()),
                    ));
                }
            }
        }
        if got < N {
            return Err(ParseError::new(
                self.pos as u64,
                format!("{}: expected {N} bytes, {got} left", what()),
            ));
        }
        self.pos += N;
        Ok(b)
    }
}

/// The `f64` at `offset` of a record, cast to `f32` as OctoMap's `(float) val`.
fn f64_at<const N: usize>(record: &[u8; N], offset: usize) -> f32 {
    let mut b = [0u8; 8];
    b.copy_from_slice(&record[offset..offset + 8]);
    f64::from_le_bytes(b) as f32
}

// ---- writing ------------------------------------------------------------------------------

fn count(n: usize, what: &str) -> u32 {
    u32::try_from(n).unwrap_or_else(|_| panic!("a .graph file holds at most 2^32-1 {what}"))
}

fn nodes_bytes(scans: &[Scan]) -> usize {
    scans
        .iter()
        .map(|s| EMPTY_NODE_BYTES + s.points.len() * VECTOR_RECORD_BYTES)
        .sum()
}

fn put_u32(out: &mut Vec<u8>, v: u32) {
    out.extend_from_slice(&v.to_le_bytes());
}

fn put_record(out: &mut Vec<u8>, tag: i32, values: &[f32]) {
    out.extend_from_slice(&tag.to_le_bytes());
    for &v in values {
        out.extend_from_slice(&f64::from(v).to_le_bytes());
    }
}

fn put_pose(out: &mut Vec<u8>, pose: &Pose) {
    put_record(out, VECTOR_TAG, &pose.translation_m);
    put_record(out, QUATERNION_TAG, &pose.rotation);
}

fn put_node(out: &mut Vec<u8>, scan: &Scan, id: u32) {
    put_u32(out, count(scan.points.len(), "points in a scan"));
    for p in &scan.points {
        put_record(out, VECTOR_TAG, p);
    }
    put_pose(out, &scan.pose);
    put_u32(out, id);
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_stream_reads_what_read_reads_and_fails_where_it_fails() {
        let mut scans = Vec::new();
        for n in [3usize, 0, 5] {
            scans.push(Scan {
                points: (0..n).map(|i| [i as f32, 0.5, -1.25]).collect(),
                colors: None,
                pose: Pose::IDENTITY,
            });
        }
        let bytes = write(&scans);
        let streamed: Result<Vec<Scan>, ParseError> =
            ScanStream::new(&bytes[..], bytes.len() as u64)
                .unwrap()
                .collect();
        assert_eq!(streamed.unwrap(), read_scans(&bytes).unwrap());
        for cut in [5, 40, bytes.len() - 1] {
            let part = &bytes[..cut];
            let want = read_scans(part).unwrap_err();
            let got = match ScanStream::new(part, part.len() as u64) {
                Err(e) => e,
                Ok(s) => s.collect::<Result<Vec<_>, _>>().unwrap_err(),
            };
            assert_eq!(got, want, "cut at {cut}");
        }
        let mut longer = bytes.clone();
        longer.push(0);
        let got = ScanStream::new(&longer[..], longer.len() as u64)
            .unwrap()
            .collect::<Result<Vec<_>, _>>()
            .unwrap_err();
        assert_eq!(got, read_scans(&longer).unwrap_err());
    }

    use super::*;

    fn sample_scans() -> Vec<Scan> {
        vec![
            Scan {
                points: vec![[1.0, -2.5, 3.25], [f32::MIN_POSITIVE, -0.0, 1e30]],
                colors: None,
                pose: Pose {
                    translation_m: [0.1, 0.2, -0.3],
                    rotation: [0.5, 0.5, -0.5, 0.5],
                },
            },
            Scan::default(),
            Scan {
                points: vec![[f32::INFINITY, f32::NEG_INFINITY, 7.0]],
                colors: Some(vec![[1, 2, 3]]),
                pose: Pose::IDENTITY,
            },
        ]
    }

    fn le_f64s(out: &mut Vec<u8>, tag: i32, v: &[f64]) {
        out.extend_from_slice(&tag.to_le_bytes());
        for x in v {
            out.extend_from_slice(&x.to_le_bytes());
        }
    }

    #[test]
    fn spherical_scan_reads_as_octomap_wrote_it() {
        let bytes = std::fs::read(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../testdata/maps/spherical_scan.graph"
        ))
        .expect("testdata/maps/spherical_scan.graph");
        let graph = read(&bytes).expect("OctoMap's own file reads");
        assert_eq!(graph.scans.len(), 1);
        assert_eq!(graph.ids, [0]);
        assert!(graph.edges.is_empty());
        let scan = &graph.scans[0];
        assert_eq!(scan.points.len(), 10201);
        assert_eq!(scan.colors, None);
        assert_eq!(scan.pose.translation_m, [1.0, 0.0, -0.5]);
        assert_eq!(scan.pose.rotation, [1.0, 0.0, 0.0, 0.0]);
        assert!(scan.points.iter().flatten().all(|v| v.is_finite()));
        // The first point, cast from the file's f64 exactly as OctoMap does.
        let f = |o: usize| f64::from_le_bytes(bytes[o..o + 8].try_into().unwrap()) as f32;
        assert_eq!(scan.points[0], [f(12), f(20), f(28)]);
        // Written back: the same bytes (OctoMap's tags are 3 and 4; the values came from f32).
        assert_eq!(write(&graph.scans), bytes);
        assert_eq!(read_scans(&bytes).unwrap(), graph.scans);
    }

    #[test]
    fn round_trip_is_bitwise() {
        let scans = sample_scans();
        let bytes = write(&scans);
        let back = read_scans(&bytes).unwrap();
        assert_eq!(back.len(), scans.len());
        for (a, b) in scans.iter().zip(&back) {
            let bits = |s: &Scan| -> Vec<u32> {
                s.points
                    .iter()
                    .flatten()
                    .chain(&s.pose.translation_m)
                    .chain(&s.pose.rotation)
                    .map(|v| v.to_bits())
                    .collect()
            };
            assert_eq!(bits(a), bits(b));
            assert_eq!(b.colors, None);
        }
        let graph = read(&bytes).unwrap();
        assert_eq!(graph.ids, [0, 1, 2]);
        assert!(graph.edges.is_empty());
        assert_eq!(
            bytes.len(),
            4 + 3 * EMPTY_NODE_BYTES + 3 * VECTOR_RECORD_BYTES + 4
        );
    }

    #[test]
    fn graph_with_edges_round_trips() {
        let mut scans = sample_scans();
        for s in &mut scans {
            s.colors = None;
        }
        let graph = Graph {
            scans,
            ids: vec![7, 3, 7],
            edges: vec![
                Edge {
                    first_id: 7,
                    second_id: 3,
                    constraint: Pose {
                        translation_m: [1.0, 2.0, 3.0],
                        rotation: [0.0, 1.0, 0.0, 0.0],
                    },
                    weight: 0.1,
                },
                Edge {
                    first_id: 99,
                    second_id: 0,
                    constraint: Pose::IDENTITY,
                    weight: f64::MAX,
                },
            ],
        };
        let bytes = graph.to_bytes();
        assert_eq!(bytes.len(), write(&graph.scans).len() + 2 * EDGE_BYTES);
        assert_eq!(read(&bytes).unwrap(), graph);
        // Missing ids are filled in with the index.
        let short = Graph {
            ids: vec![5],
            ..graph.clone()
        };
        assert_eq!(read(&write_graph(&short)).unwrap().ids, [5, 1, 2]);
    }

    #[test]
    fn values_are_cast_as_octomap_does_and_tags_are_not_checked() {
        let mut b = Vec::new();
        b.extend_from_slice(&1u32.to_le_bytes());
        b.extend_from_slice(&1u32.to_le_bytes());
        le_f64s(&mut b, -17, &[0.1, 1e300, -1e-300]);
        le_f64s(&mut b, 0, &[1.0 + 1e-12, 2.0, 3.0]);
        le_f64s(&mut b, i32::MAX, &[1.0, 0.0, 0.0, f64::NAN]);
        b.extend_from_slice(&42u32.to_le_bytes());
        b.extend_from_slice(&0u32.to_le_bytes());
        let g = read(&b).unwrap();
        let s = &g.scans[0];
        assert_eq!(s.points[0][0], 0.1f64 as f32);
        assert_eq!(s.points[0][1], f32::INFINITY);
        assert_eq!(s.points[0][2].to_bits(), (-0.0f32).to_bits());
        assert_eq!(s.pose.translation_m, [1.0, 2.0, 3.0]);
        assert!(s.pose.rotation[3].is_nan());
        assert_eq!(g.ids, [42]);
    }

    #[test]
    fn truncation_names_offset_and_record() {
        let scans = vec![
            Scan {
                points: vec![[1.0; 3]; 3],
                ..Scan::default()
            },
            Scan {
                points: vec![[2.0; 3]; 20],
                ..Scan::default()
            },
        ];
        let bytes = write(&scans);
        // Node 2's point 17: after node 1 (4 + 3 x 28 + 64 + 4) and node 2's count.
        let node2 = 4 + EMPTY_NODE_BYTES + 3 * VECTOR_RECORD_BYTES;
        let point17 = node2 + 4 + 16 * VECTOR_RECORD_BYTES;
        let err = read(&bytes[..point17 + 5]).unwrap_err();
        assert_eq!(err.offset, point17 as u64);
        assert_eq!(
            err.to_string(),
            format!("offset {point17}: node 2 of 2, point 17 of 20: expected 28 bytes, 5 left")
        );
        let cases = [
            (0, "node count: expected 4 bytes, 0 left"),
            (3, "node count: expected 4 bytes, 3 left"),
            (4, "node 1 of 2, point count: expected 4 bytes, 0 left"),
            (
                4 + 4 + 3 * VECTOR_RECORD_BYTES,
                "node 1 of 2, pose translation: expected 28 bytes, 0 left",
            ),
            (
                4 + 4 + 3 * VECTOR_RECORD_BYTES + VECTOR_RECORD_BYTES + 35,
                "node 1 of 2, pose rotation: expected 36 bytes, 35 left",
            ),
            (node2 - 1, "node 1 of 2, id: expected 4 bytes, 3 left"),
            (bytes.len() - 4, "edge count: expected 4 bytes, 0 left"),
        ];
        for (cut, message) in cases {
            let err = read(&bytes[..cut]).unwrap_err();
            assert_eq!(err.message, message, "cut at {cut}");
        }
        // Every prefix fails, none panics.
        for cut in 0..bytes.len() {
            assert!(
                read(&bytes[..cut]).is_err(),
                "prefix of {cut} bytes accepted"
            );
        }
    }

    #[test]
    fn edge_truncation_and_trailing_bytes() {
        let graph = Graph {
            scans: vec![Scan::default()],
            ids: vec![0],
            edges: vec![Edge {
                first_id: 0,
                second_id: 0,
                constraint: Pose::IDENTITY,
                weight: 1.0,
            }],
        };
        let bytes = graph.to_bytes();
        let edge = 4 + EMPTY_NODE_BYTES + 4;
        let err = read(&bytes[..bytes.len() - 1]).unwrap_err();
        assert_eq!(err.offset, (bytes.len() - 8) as u64);
        assert_eq!(err.message, "edge 1 of 1, weight: expected 8 bytes, 7 left");
        let err = read(&bytes[..edge + 6]).unwrap_err();
        assert_eq!(
            err.message,
            "edge 1 of 1, second id: expected 4 bytes, 2 left"
        );
        let err = read(&bytes[..edge + 8 + 30]).unwrap_err();
        assert_eq!(
            err.message,
            "edge 1 of 1, constraint rotation: expected 36 bytes, 2 left"
        );
        let mut long = bytes.clone();
        long.extend_from_slice(&[0, 0]);
        let err = read(&long).unwrap_err();
        assert_eq!(err.offset, bytes.len() as u64);
        assert_eq!(err.message, "2 bytes after the last of 1 edges");
    }

    #[test]
    fn huge_counts_fail_without_allocating() {
        // 4e9 nodes, then 4e9 points, then 4e9 edges: each in a tiny file.
        let mut b = u32::MAX.to_le_bytes().to_vec();
        b.extend_from_slice(&4_000_000_000u32.to_le_bytes());
        b.extend_from_slice(&[0; 10]);
        let err = read(&b).unwrap_err();
        assert_eq!(err.offset, 8);
        assert_eq!(
            err.message,
            format!(
                "node 1 of {}, point 1 of 4000000000: expected 28 bytes, 10 left",
                u32::MAX
            )
        );
        let mut b = write(&[]);
        b.truncate(4);
        b.extend_from_slice(&u32::MAX.to_le_bytes());
        assert_eq!(
            read(&b).unwrap_err().message,
            format!("edge 1 of {}, first id: expected 4 bytes, 0 left", u32::MAX)
        );
        assert_eq!(capped(u32::MAX, 100, VECTOR_RECORD_BYTES), 3);
    }

    #[test]
    fn empty_graph() {
        let bytes = write(&[]);
        assert_eq!(bytes, [0; 8]);
        assert_eq!(read(&bytes).unwrap(), Graph::default());
    }
}
