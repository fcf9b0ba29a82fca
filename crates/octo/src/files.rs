//! OctoMap's map files: `.ot` (full log-odds, `OcTree` or `ColorOcTree`) and `.bt` (the
//! maximum-likelihood "bonsai tree", 2 bits per child), written byte for byte as OctoMap 1.9
//! writes them and read as OctoMap reads them.
//!
//! Both start with an ASCII header: a first line that names the format (`# Octomap OcTree
//! file` or `# Octomap OcTree binary file`; it must match), comment lines, then `id TYPE`,
//! `size N` (nodes), `res R` and `data`, after which the body follows:
//! - `.ot`: every node in pre-order: `f32` log-odds (little-endian), for `ColorOcTree` then
//!   `u8` r, g, b, then a `u8` whose bit i says child i exists.
//! - `.bt`: for every inner node in pre-order, 2 bytes: child i's code at bits `2 * (i % 4)` of
//!   byte `i / 4` (0 unknown, 1 free leaf, 2 occupied leaf, 3 inner, whose record follows). A
//!   `ColorOcTree`'s `.bt` (`convert_octree` of a coloured `.ot`) has the same body, no colours:
//!   it reads as an `OcTree`.
//!
//! The readers never panic on any input; errors give the byte offset and what was expected.
//! Allocation is bounded by the input: every node read consumes at least one byte.

use super::ParseError;
use super::math::MeanColor;
use super::tree::{NodeRef, NodeView, OcTree, TREE_DEPTH, WHITE};

/// First line of a `.ot` file.
pub const OT_HEADER: &str = "# Octomap OcTree file";
/// First line of a `.bt` file.
pub const BT_HEADER: &str = "# Octomap OcTree binary file";
const COMMENT: &str =
    "# (feel free to add / change comments, but leave the first line as it is!)\n#\n";

/// A number as C++'s `std::ostream << double` prints it (`%g`, 6 significant digits).
pub fn format_g6(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    if !v.is_finite() {
        return format!("{v}");
    }
    let exp = v.abs().log10().floor() as i32;
    let s = format!("{:.5e}", v);
    // Re-derive the exponent after rounding (9.999995 rounds up to 1.00000e1).
    let (mant, e) = s.split_once('e').unwrap_or((&s, "0"));
    let e: i32 = e.parse().unwrap_or(exp);
    if !(-4..6).contains(&e) {
        let mant = trim_zeros(mant);
        let sign = if e < 0 { '-' } else { '+' };
        return format!("{mant}e{sign}{:02}", e.abs());
    }
    let decimals = (5 - e).max(0) as usize;
    trim_zeros(&format!("{:.*}", decimals, v)).to_string()
}

fn trim_zeros(s: &str) -> &str {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.')
    } else {
        s
    }
}

fn header(first: &str, id: &str, size: usize, res: f64) -> Vec<u8> {
    format!(
        "{first}\n{COMMENT}id {id}\nsize {size}\nres {}\ndata\n",
        format_g6(res)
    )
    .into_bytes()
}

/// The type name OctoMap writes in `id`.
pub fn tree_type(tree: &OcTree) -> &'static str {
    if tree.is_colored() {
        "ColorOcTree"
    } else {
        "OcTree"
    }
}

/// Bytes of a node's `.ot` record: log-odds, a coloured tree's r, g, b, the child mask.
fn ot_record_bytes(tree: &OcTree) -> usize {
    if tree.is_colored() { 8 } else { 5 }
}

/// A tree's `.ot` header.
fn ot_header(tree: &OcTree) -> Vec<u8> {
    header(
        OT_HEADER,
        tree_type(tree),
        tree.num_nodes(),
        tree.resolution_m(),
    )
}

/// A tree's `.ot` header, with room for its nodes' records.
fn ot_start(tree: &OcTree) -> Vec<u8> {
    let mut out = ot_header(tree);
    out.reserve(tree.num_nodes() * ot_record_bytes(tree));
    out
}

/// The `.ot` file of a tree (`ColorOcTree` when the tree keeps colours).
pub fn write_ot(tree: &OcTree) -> Vec<u8> {
    let mut out = ot_start(tree);
    if let Some(root) = tree.root() {
        write_ot_node(tree, root, &mut out);
    }
    out
}

/// A `.ot` file in pieces ([`write_ot_threads`]): the header and the records above the
/// subtrees written apart, with each subtree's records to splice in at its place. Written out
/// piece by piece, not joined into one buffer first.
#[derive(Debug, Default)]
pub struct OtPieces {
    /// The header and the records above the split.
    top: Vec<u8>,
    /// Where in `top` each subtree goes (ascending), and its records.
    splices: Vec<(usize, Vec<u8>)>,
}

impl OtPieces {
    /// The file's bytes in order, piece by piece.
    pub fn pieces(&self) -> impl Iterator<Item = &[u8]> {
        let mut at = 0;
        self.splices
            .iter()
            .flat_map(move |(pos, part)| {
                let before = &self.top[at..*pos];
                at = *pos;
                [before, part.as_slice()]
            })
            .chain(std::iter::once_with(move || {
                &self.top[self.splices.last().map_or(0, |s| s.0)..]
            }))
    }

    /// The whole file in one buffer.
    pub fn joined(&self) -> Vec<u8> {
        self.pieces().flatten().copied().collect()
    }
}

/// [`write_ot`] on up to `threads` threads: the subtrees [`OT_SPLIT_DEPTH`] levels below the
/// root are written apart, each by the first thread free, to be spliced in under the records
/// above them. The same bytes as [`write_ot`], in pieces.
pub fn write_ot_threads(tree: &OcTree, threads: usize) -> OtPieces {
    let Some(root) = tree.root().filter(|_| threads > 1) else {
        return OtPieces {
            top: write_ot(tree),
            splices: Vec::new(),
        };
    };
    let mut jobs = Vec::new();
    split_nodes(tree, root, 0, &mut jobs);
    let next = std::sync::atomic::AtomicUsize::new(0);
    let (jobs, next) = (&jobs, &next);
    let mut parts: Vec<Option<(Vec<u8>, [u8; 3])>> = vec![None; jobs.len()];
    std::thread::scope(|sc| {
        let workers: Vec<_> = (0..threads.min(jobs.len()))
            .map(|_| {
                sc.spawn(move || {
                    let mut done = Vec::new();
                    loop {
                        let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some(&r) = jobs.get(k) else { break done };
                        let mut bytes = Vec::new();
                        let color = write_ot_node(tree, r, &mut bytes);
                        done.push((k, bytes, color));
                    }
                })
            })
            .collect();
        for w in workers {
            // A worker only writes into its own buffers: it does not fail.
            for (k, bytes, color) in w.join().unwrap_or_default() {
                parts[k] = Some((bytes, color));
            }
        }
    });
    let mut out = OtPieces {
        top: ot_header(tree),
        splices: Vec::with_capacity(jobs.len()),
    };
    let mut parts = parts.into_iter();
    write_ot_top(tree, root, 0, &mut parts, &mut out.top, &mut out.splices);
    out
}

/// The depth whose subtrees [`write_ot_threads`] writes apart (up to 64 of them).
const OT_SPLIT_DEPTH: u32 = 2;

/// The nodes at [`OT_SPLIT_DEPTH`] below node `r` (at `depth`), in pre-order.
fn split_nodes(tree: &OcTree, r: NodeRef, depth: u32, out: &mut Vec<NodeRef>) {
    if depth == OT_SPLIT_DEPTH {
        out.push(r);
        return;
    }
    for i in 0..8 {
        if let Some(c) = tree.child(r, i) {
            split_nodes(tree, c, depth + 1, out);
        }
    }
}

/// [`write_ot_node`] above [`OT_SPLIT_DEPTH`], taking the subtrees there, in pre-order, from
/// `parts` to splice in (a missing one, which [`write_ot_threads`] never leaves, is written
/// here).
fn write_ot_top(
    tree: &OcTree,
    r: NodeRef,
    depth: u32,
    parts: &mut impl Iterator<Item = Option<(Vec<u8>, [u8; 3])>>,
    top: &mut Vec<u8>,
    splices: &mut Vec<(usize, Vec<u8>)>,
) -> [u8; 3] {
    if depth == OT_SPLIT_DEPTH {
        return match parts.next().flatten() {
            Some((bytes, color)) => {
                splices.push((top.len(), bytes));
                color
            }
            None => write_ot_node(tree, r, top),
        };
    }
    // The records above the split are all in `top`: an inner node's colour is filled in there.
    write_ot_with(tree, r, top, |top, c| {
        write_ot_top(tree, c, depth + 1, parts, top, splices)
    })
}

/// The size of the `.ot` file of a tree, without writing it.
pub fn ot_size(tree: &OcTree) -> usize {
    ot_header(tree).len() + tree.num_nodes() * ot_record_bytes(tree)
}

/// Writes node `r` and its subtree in pre-order; returns the colour the node is written with
/// (a coloured tree's), which its parent's mean takes.
///
/// An inner node's colour is the mean of its children's set colours (OctoMap's
/// `getAverageChildColor`, applied from the leaves up), white when none is set. It is known only
/// once the children are written, so its three bytes are written as white and filled in then:
/// each node is visited once, where computing each inner node's mean afresh visited every node
/// once per ancestor.
fn write_ot_node(tree: &OcTree, r: NodeRef, out: &mut Vec<u8>) -> [u8; 3] {
    write_ot_with(tree, r, out, |out, c| write_ot_node(tree, c, out))
}

/// Node `r`'s record, then each child's subtree as `child` writes it (returning the colour
/// the child is written with), then an inner node's mean colour filled in; the colour `r` is
/// written with.
#[inline(always)]
fn write_ot_with(
    tree: &OcTree,
    r: NodeRef,
    out: &mut Vec<u8>,
    mut child: impl FnMut(&mut Vec<u8>, NodeRef) -> [u8; 3],
) -> [u8; 3] {
    let (color_at, v) = write_ot_record(tree, r, out);
    if !v.has_children() {
        return v.color.unwrap_or(WHITE);
    }
    let mut mean = MeanColor::default();
    for c in tree.children_of(&v) {
        mean.add(child(out, c));
    }
    let mean = mean.mean().unwrap_or(WHITE);
    if tree.is_colored() {
        out[color_at..color_at + 3].copy_from_slice(&mean);
    }
    mean
}

/// Node `r`'s own `.ot` record (its colour, in a coloured tree, its own: an inner node's is
/// filled in later); where its colour is in `out`, and the node.
fn write_ot_record(tree: &OcTree, r: NodeRef, out: &mut Vec<u8>) -> (usize, NodeView) {
    let v = tree.node(r);
    let color_at = out.len() + 4;
    let [a, b, c, d] = v.log_odds.to_le_bytes();
    if tree.is_colored() {
        let [r, g, bl] = v.color.unwrap_or(WHITE);
        out.extend_from_slice(&[a, b, c, d, r, g, bl, v.child_mask()]);
    } else {
        out.extend_from_slice(&[a, b, c, d, v.child_mask()]);
    }
    (color_at, v)
}

/// The `.bt` file of a tree, as `graph2tree` writes it: a maximum-likelihood copy, pruned twice
/// (OctoMap's `prune()` stops at the first depth where nothing collapses).
pub fn write_bt(tree: &OcTree) -> Vec<u8> {
    // A .bt holds no colour: prune a colour-blind copy, as an OcTree would be.
    let mut ml = tree.clone();
    ml.drop_colors();
    ml.to_max_likelihood(2);
    let mut out = header(BT_HEADER, "OcTree", ml.num_nodes(), ml.resolution_m());
    if let Some(root) = ml.root() {
        write_bt_node(&ml, root, &mut out);
    }
    out
}

/// A node's `.bt` record: child i's 2-bit code (0 unknown, 1 free leaf, 2 occupied leaf, 3 inner)
/// at bits `2 * (i % 4)` of byte `i / 4`.
pub(crate) fn bt_record(tree: &OcTree, r: NodeRef) -> [u8; 2] {
    let mut bytes = [0u8; 2];
    for i in 0..8 {
        if let Some(c) = tree.child(r, i) {
            let v = tree.node(c);
            let code = if v.has_children() {
                3
            } else if v.log_odds >= 0.0 {
                2
            } else {
                1
            };
            bytes[i / 4] |= code << (2 * (i % 4));
        }
    }
    bytes
}

fn write_bt_node(tree: &OcTree, r: NodeRef, out: &mut Vec<u8>) {
    out.extend_from_slice(&bt_record(tree, r));
    for i in 0..8 {
        if let Some(c) = tree.child(r, i)
            && tree.node(c).has_children()
        {
            write_bt_node(tree, c, out);
        }
    }
}

/// What kind of map file a byte string is, from its first line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MapFormat {
    /// `.ot`.
    Ot,
    /// `.bt`.
    Bt,
}

/// The header fields of a map file.
#[derive(Debug, Clone, PartialEq)]
pub struct MapHeader {
    /// Which body follows.
    pub format: MapFormat,
    /// The tree type (`OcTree`, `ColorOcTree`, ...).
    pub id: String,
    /// The node count the header claims.
    pub size: u64,
    /// Voxel edge in metres.
    pub resolution_m: f64,
    /// Offset of the body.
    pub body_offset: usize,
}

/// Reads a map file's header.
pub fn read_header(bytes: &[u8]) -> Result<MapHeader, ParseError> {
    let line_end = bytes
        .iter()
        .position(|&b| b == b'\n')
        .ok_or_else(|| ParseError::new(0, "not an OctoMap file: no header line"))?;
    let first = String::from_utf8_lossy(&bytes[..line_end]);
    let first = first.trim_end_matches('\r');
    let format = if first.starts_with(BT_HEADER) {
        MapFormat::Bt
    } else if first.starts_with(OT_HEADER) {
        MapFormat::Ot
    } else {
        return Err(ParseError::new(
            0,
            format!(
                "not an OctoMap file: first line {first:?}, expected {OT_HEADER:?} or {BT_HEADER:?}"
            ),
        ));
    };
    let mut pos = line_end + 1;
    let (mut id, mut size, mut res) = (None, None, None);
    loop {
        if pos >= bytes.len() {
            return Err(ParseError::new(
                pos as u64,
                "header ends before its `data` line",
            ));
        }
        let end = bytes[pos..]
            .iter()
            .position(|&b| b == b'\n')
            .map_or(bytes.len(), |e| pos + e);
        let line = String::from_utf8_lossy(&bytes[pos..end]);
        let line = line.trim();
        let at = pos as u64;
        pos = (end + 1).min(bytes.len().max(end + 1));
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let (key, value) = line.split_once(char::is_whitespace).unwrap_or((line, ""));
        let value = value.trim();
        match key {
            "data" => break,
            "id" => id = Some(value.to_string()),
            "size" => {
                size = Some(value.parse::<u64>().map_err(|_| {
                    ParseError::new(
                        at,
                        format!("header size: expected a node count, found {value:?}"),
                    )
                })?)
            }
            "res" => {
                let r = value.parse::<f64>().map_err(|_| {
                    ParseError::new(
                        at,
                        format!("header res: expected a number, found {value:?}"),
                    )
                })?;
                if !(r.is_finite() && r > 0.0) {
                    return Err(ParseError::new(
                        at,
                        format!("header res: expected a positive resolution, found {value}"),
                    ));
                }
                res = Some(r)
            }
            // OctoMap warns about other lines and reads on.
            _ => {}
        }
    }
    let id = id.ok_or_else(|| ParseError::new(pos as u64, "header has no `id` line"))?;
    let resolution_m =
        res.ok_or_else(|| ParseError::new(pos as u64, "header has no `res` line"))?;
    let size = size.ok_or_else(|| ParseError::new(pos as u64, "header has no `size` line"))?;
    Ok(MapHeader {
        format,
        id,
        size,
        resolution_m,
        body_offset: pos.min(bytes.len()),
    })
}

/// Reads a `.ot` (`OcTree` or `ColorOcTree`) or `.bt` file.
pub fn read_map(bytes: &[u8]) -> Result<OcTree, ParseError> {
    let h = read_header(bytes)?;
    let tree = match h.format {
        MapFormat::Ot => read_ot_body(bytes, &h)?,
        MapFormat::Bt => read_bt_body(bytes, &h)?,
    };
    if tree.num_nodes() as u64 != h.size {
        return Err(ParseError::new(
            h.body_offset as u64,
            format!(
                "header size {} but the body holds {} nodes",
                h.size,
                tree.num_nodes()
            ),
        ));
    }
    Ok(tree)
}

fn read_ot_body(bytes: &[u8], h: &MapHeader) -> Result<OcTree, ParseError> {
    let colored = match h.id.as_str() {
        "OcTree" => false,
        "ColorOcTree" => true,
        other => {
            return Err(ParseError::new(
                h.body_offset as u64,
                format!("tree type {other:?} is not supported (OcTree or ColorOcTree)"),
            ));
        }
    };
    let per = if colored { 8 } else { 5 };
    let mut pos = h.body_offset;
    let empty = h.size == 0;
    OcTree::from_preorder(
        h.resolution_m,
        colored,
        |depth| {
            if bytes.len() < pos + per {
                return Err(ParseError::new(
                    pos as u64,
                    format!(
                        "node record at depth {depth}: expected {per} bytes, {} left",
                        bytes.len() - pos.min(bytes.len())
                    ),
                ));
            }
            let v =
                f32::from_le_bytes([bytes[pos], bytes[pos + 1], bytes[pos + 2], bytes[pos + 3]]);
            if !v.is_finite() {
                return Err(ParseError::new(
                    pos as u64,
                    format!("node log-odds: expected a finite number, found {v}"),
                ));
            }
            let c = colored.then(|| [bytes[pos + 4], bytes[pos + 5], bytes[pos + 6]]);
            let mask = bytes[pos + per - 1];
            if depth == TREE_DEPTH && mask != 0 {
                return Err(ParseError::new(
                    (pos + per - 1) as u64,
                    format!(
                        "node at depth 16 claims children (mask {mask:#04x}): the tree has 16 levels"
                    ),
                ));
            }
            pos += per;
            Ok((v, c.filter(|c| *c != [255, 255, 255]), mask))
        },
        empty,
    )
}

/// A `.bt` body: the same for `OcTree` and `ColorOcTree` (OctoMap's `writeBinary` writes the
/// occupancy bits of any occupancy tree, and a `ColorOcTree`'s pruning is by occupancy only), so
/// both read as a colourless tree.
fn read_bt_body(bytes: &[u8], h: &MapHeader) -> Result<OcTree, ParseError> {
    if h.id != "OcTree" && h.id != "ColorOcTree" {
        return Err(ParseError::new(
            h.body_offset as u64,
            format!(
                "a .bt file holds an OcTree or a ColorOcTree, found id {:?}",
                h.id
            ),
        ));
    }
    if h.size == 0 {
        return Ok(OcTree::new(h.resolution_m));
    }
    let p = crate::tree::Params::default();
    // The nodes in pre-order: (log-odds, child mask); inner values are set afterwards.
    let mut nodes: Vec<(f32, u8)> = Vec::new();
    let mut pos = h.body_offset;
    bt_node(
        bytes,
        &mut pos,
        0,
        (p.clamp_min_log, p.clamp_max_log),
        &mut nodes,
    )?;
    let mut it = nodes.into_iter();
    let mut tree = OcTree::from_preorder(
        h.resolution_m,
        false,
        |_| {
            let (v, m) = it.next().unwrap_or((0.0, 0));
            Ok::<_, ParseError>((v, None, m))
        },
        false,
    )?;
    tree.recompute_inner_values();
    Ok(tree)
}

fn bt_node(
    bytes: &[u8],
    pos: &mut usize,
    depth: u32,
    clamp: (f32, f32),
    nodes: &mut Vec<(f32, u8)>,
) -> Result<(), ParseError> {
    if bytes.len() < *pos + 2 {
        return Err(ParseError::new(
            *pos as u64,
            format!(
                "inner node at depth {depth}: expected 2 bytes, {} left",
                bytes.len() - (*pos).min(bytes.len())
            ),
        ));
    }
    if depth >= TREE_DEPTH {
        return Err(ParseError::new(
            *pos as u64,
            "inner node at depth 16: the tree has 16 levels",
        ));
    }
    let b = [bytes[*pos], bytes[*pos + 1]];
    *pos += 2;
    let codes: Vec<u8> = (0..8).map(|i| (b[i / 4] >> (2 * (i % 4))) & 3).collect();
    let mask = codes
        .iter()
        .enumerate()
        .fold(0u8, |m, (i, &c)| if c != 0 { m | (1 << i) } else { m });
    // An inner record without children reads as OctoMap's maximum of no children, -FLT_MAX.
    nodes.push((if mask == 0 { -f32::MAX } else { 0.0 }, mask));
    for c in codes {
        match c {
            1 => nodes.push((clamp.0, 0)),
            2 => nodes.push((clamp.1, 0)),
            3 => bt_node(bytes, pos, depth + 1, clamp, nodes)?,
            _ => {}
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Pose, Scan};

    /// Written on several threads, a `.ot` is the one-thread `.ot` byte for byte: coloured and
    /// plain, empty, a lone root, leaves above the split depth, and a survey's map.
    #[test]
    fn a_ot_on_threads_is_the_one_thread_ot() {
        let mut trees = vec![OcTree::new(0.1)];
        let mut lone = OcTree::new(0.1);
        lone.insert_scan(
            &Scan {
                points: vec![[0.05, 0.05, 0.05]],
                colors: None,
                pose: Pose::IDENTITY,
            },
            None,
        );
        trees.push(lone);
        // A root whose children are leaves (above the split depth), read from a `.ot`: its
        // first child a leaf, its second inner with one leaf child.
        let mut small = header(OT_HEADER, "ColorOcTree", 4, 0.1);
        for (v, color, mask) in [
            (0.5f32, [1u8, 2, 3], 0b11u8),
            (0.4, [9, 9, 9], 0),
            (0.5, [4, 5, 6], 1),
            (0.5, [4, 5, 6], 0),
        ] {
            small.extend_from_slice(&v.to_le_bytes());
            small.extend_from_slice(&color);
            small.push(mask);
        }
        trees.push(read_map(&small).expect("the small .ot reads"));
        for colored in [false, true] {
            for res in [0.1, 400.0] {
                let mut t = OcTree::new(res);
                if colored {
                    t.enable_color();
                }
                for scan in crate::synth::survey(&crate::synth::SurveyParams {
                    scans: 3,
                    ..Default::default()
                }) {
                    t.insert_scan(&scan, None);
                }
                trees.push(t);
            }
        }
        for (k, t) in trees.iter().enumerate() {
            let one = write_ot(t);
            for threads in [1, 2, 3, 8] {
                assert!(
                    write_ot_threads(t, threads).joined() == one,
                    "tree {k}, {threads} threads"
                );
            }
        }
    }

    #[test]
    fn g6_matches_cpp() {
        assert_eq!(format_g6(0.1), "0.1");
        assert_eq!(format_g6(0.15), "0.15");
        assert_eq!(format_g6(0.08), "0.08");
        assert_eq!(format_g6(0.05), "0.05");
        assert_eq!(format_g6(1.0), "1");
        assert_eq!(format_g6(0.123456789), "0.123457");
        assert_eq!(format_g6(0.00001), "1e-05");
        assert_eq!(format_g6(2.5), "2.5");
    }

    fn sample_tree(colored: bool) -> OcTree {
        let mut t = OcTree::new(0.1);
        if colored {
            t.enable_color();
        }
        let mut pts = Vec::new();
        let mut cols = Vec::new();
        for i in 0..40 {
            for j in 0..40 {
                pts.push([i as f32 * 0.07 - 1.0, j as f32 * 0.05 - 1.0, 2.0]);
                cols.push([i as u8 * 5, j as u8 * 5, 100]);
            }
        }
        t.insert_scan(
            &Scan {
                points: pts,
                colors: Some(cols),
                pose: Pose::IDENTITY,
            },
            None,
        );
        t
    }

    #[test]
    fn ot_round_trip_is_byte_identical() {
        for colored in [false, true] {
            let t = sample_tree(colored);
            let bytes = write_ot(&t);
            assert_eq!(bytes.len(), ot_size(&t));
            let back = read_map(&bytes).unwrap();
            assert_eq!(back.num_nodes(), t.num_nodes());
            assert_eq!(write_ot(&back), bytes);
        }
    }

    #[test]
    fn bt_round_trip() {
        let t = sample_tree(false);
        let bytes = write_bt(&t);
        let back = read_map(&bytes).unwrap();
        assert_eq!(write_bt(&back), bytes);
    }

    #[test]
    fn a_color_octree_bt_reads_as_its_octree() {
        let t = sample_tree(false);
        let bytes = write_bt(&t);
        let body = &bytes[read_header(&bytes).unwrap().body_offset..];
        let as_type = |id: &str| {
            let mut ml = t.clone();
            ml.to_max_likelihood(2);
            [header(BT_HEADER, id, ml.num_nodes(), 0.1), body.to_vec()].concat()
        };
        let file = as_type("ColorOcTree");
        let back = read_map(&file).unwrap();
        assert!(!back.is_colored());
        assert_eq!(write_bt(&back), bytes);
        let e = read_map(&file[..file.len() - 3]).unwrap_err();
        assert!(e.message.contains("expected 2 bytes"), "{e}");
        let e = read_map(&as_type("CountingOcTree")).unwrap_err();
        assert!(e.message.contains("CountingOcTree"), "{e}");
    }

    #[test]
    fn truncated_and_bad_headers_are_errors_with_offsets() {
        let t = sample_tree(false);
        let bytes = write_ot(&t);
        let h = read_header(&bytes).unwrap();
        for cut in [h.body_offset + 3, bytes.len() - 1] {
            let e = read_map(&bytes[..cut]).unwrap_err();
            assert!(e.offset as usize <= cut, "{e}");
        }
        assert!(
            read_map(b"hello\n")
                .unwrap_err()
                .message
                .contains("first line")
        );
        let e = read_map(b"# Octomap OcTree file\nid OcTree\nsize 1\nres -1\ndata\n").unwrap_err();
        assert!(e.message.contains("res"), "{e}");
        let bt = write_bt(&t);
        let e = read_map(&bt[..bt.len() - 1]).unwrap_err();
        assert!(e.message.contains("expected 2 bytes"), "{e}");
    }
}
