//! The 5-4-3 tree: root tiles and children, internal nodes of 32^3 and 16^3 slots, leaves of
//! 8^3 voxels (`openvdb/tree/RootNode.h`, `InternalNode.h`, `LeafNode.h`).
//!
//! The file holds the whole topology first, then the leaf buffers in the same order. The
//! topology is parsed twice, so that nothing per leaf is kept between the two (a file larger
//! than memory has more leaves than memory, issue 19): the first walk passes the tiles to the
//! visitor and finds where the buffers begin; the second walks the topology again with a
//! second reader, in lockstep with the buffers, handing each leaf's origin and value mask to
//! its buffer. Parsing the internal nodes twice costs little: they are 1/64 and less of the
//! leaves. Nothing is allocated from a count in the file before the bytes that the count
//! implies are known to be there.

use std::collections::HashSet;

use glam::IVec3;

use super::bytes::{bit, ones, Reader};
use super::values::Codec;
use crate::error::Result;

/// log2 of the voxels per side covered by a tile at each level.
pub const ROOT_TILE_LOG2: u32 = 12;
pub const INTERNAL5_TILE_LOG2: u32 = 7;
pub const INTERNAL4_TILE_LOG2: u32 = 3;

/// Receives what the tree holds. Values are `comps` numbers each; leaf values are in VDB
/// order (offset `x << 6 | y << 3 | z`, z fastest).
pub(crate) trait Visitor {
    /// The root's background value, before anything else.
    fn background(&mut self, _value: &[f64]) -> Result<()> {
        Ok(())
    }
    /// A tile covering `(1 << log2)^3` voxels from `origin`. Called for every active tile and
    /// for inactive tiles whose value differs from the background.
    fn tile(&mut self, origin: IVec3, log2: u32, value: &[f64], active: bool) -> Result<()>;
    fn leaf(&mut self, origin: IVec3, mask: &[u64; 8], values: &[f64]) -> Result<()>;
    /// The leaf at `origin`, from the topology, before its buffer is read: false steps over
    /// the buffer without decoding it (and `leaf` is not called for it).
    fn wants_leaf(&mut self, _origin: IVec3) -> bool {
        true
    }
    /// Stop after the topology: tiles and `wants_leaf` of every leaf, no leaf buffer read.
    fn topology_only(&self) -> bool {
        false
    }
}

/// Whether the box of `(1 << log2)^3` voxels at `origin` meets the index box `lo..hi`.
fn meets(origin: IVec3, log2: u32, (lo, hi): (IVec3, IVec3)) -> bool {
    (origin + IVec3::splat(1 << log2)).cmpgt(lo).all() && origin.cmplt(hi).all()
}

/// Passes on only the tiles that meet the region.
struct InRegion<'a> {
    inner: &'a mut dyn Visitor,
    region: (IVec3, IVec3),
}

impl Visitor for InRegion<'_> {
    fn background(&mut self, value: &[f64]) -> Result<()> {
        self.inner.background(value)
    }
    fn tile(&mut self, origin: IVec3, log2: u32, value: &[f64], active: bool) -> Result<()> {
        if meets(origin, log2, self.region) { self.inner.tile(origin, log2, value, active) } else { Ok(()) }
    }
    fn leaf(&mut self, origin: IVec3, mask: &[u64; 8], values: &[f64]) -> Result<()> {
        self.inner.leaf(origin, mask, values)
    }
    fn wants_leaf(&mut self, origin: IVec3) -> bool {
        meets(origin, INTERNAL4_TILE_LOG2, self.region) && self.inner.wants_leaf(origin)
    }
    fn topology_only(&self) -> bool {
        self.inner.topology_only()
    }
}

/// Reads topology and buffers of one tree at the reader's position, passing on (with
/// `region`) only the tiles and leaves that meet the index box `lo..hi`: the other leaves'
/// buffers are stepped over without decoding. Returns how many leaves were skipped.
pub(crate) fn read_tree_region(r: &mut Reader, codec: &mut Codec, visitor: &mut dyn Visitor, region: Option<(IVec3, IVec3)>) -> Result<usize> {
    let mut filtered;
    let visitor: &mut dyn Visitor = match region {
        Some(region) => {
            filtered = InRegion { inner: visitor, region };
            &mut filtered
        }
        None => visitor,
    };
    let buffers = r.i32("buffer count")?;
    if buffers != 1 {
        return Err(r.err(format!("tree has {buffers} buffers; only 1 is supported")));
    }
    let full = codec.kind.full_size();
    let bg_bytes = r.bytes(full, "background value")?;
    let mut bg = vec![0.0; codec.kind.comps];
    codec.kind.decode_full(bg_bytes, &mut bg);
    if bg.iter().any(|v| !v.is_finite()) {
        return Err(r.err("background value is not finite"));
    }
    codec.background = bg.clone();
    visitor.background(&bg)?;
    let num_tiles = r.u32("root tile count")? as u64;
    let num_children = r.u32("root child count")? as u64;
    let tile_bytes = 12 + full as u64 + 1;
    // Smallest possible internal node: origin, two masks.
    let child_bytes = 12 + 2 * 4096;
    if num_tiles.saturating_mul(tile_bytes).saturating_add(num_children.saturating_mul(child_bytes)) > r.remaining() as u64 {
        return Err(r.err(format!(
            "root claims {num_tiles} tiles and {num_children} children, more than the {} bytes left can hold",
            r.remaining()
        )));
    }
    let mut seen = HashSet::new();
    let mut value = vec![0.0; codec.kind.comps];
    let root_origin = |r: &mut Reader, seen: &mut HashSet<IVec3>, what: &str| -> Result<IVec3> {
        let o = IVec3::new(r.i32(what)?, r.i32(what)?, r.i32(what)?);
        if o & IVec3::splat((1 << ROOT_TILE_LOG2) - 1) != IVec3::ZERO {
            return Err(r.err(format!("{what} {o} is not a multiple of 4096")));
        }
        if !seen.insert(o) {
            return Err(r.err(format!("{what} {o} appears twice in the root")));
        }
        Ok(o)
    };
    for _ in 0..num_tiles {
        let origin = root_origin(r, &mut seen, "root tile origin")?;
        let b = r.bytes(full, "root tile value")?;
        codec.kind.decode_full(b, &mut value);
        let active = r.u8("root tile active flag")? != 0;
        if active || value != bg {
            visitor.tile(origin, ROOT_TILE_LOG2, &value, active)?;
        }
    }
    let codec = &*codec;
    // First walk: tiles to the visitor (and, topology only, each leaf's origin), leaves counted.
    let children_at = r.pos();
    let mut scratch = Vec::new();
    let mut leaves = 0usize;
    let mut children = Vec::new();
    for _ in 0..num_children {
        let origin = root_origin(r, &mut seen, "root child origin")?;
        children.push(origin);
        let mut count = |_: IVec3, _: [u64; 8]| {
            leaves += 1;
            Ok(())
        };
        read_internal(r, codec, Some(&mut *visitor), origin, 5, &mut count, &mut scratch)?;
    }
    if visitor.topology_only() {
        return Ok(leaves);
    }
    // Second walk, in lockstep: `t` reads the topology again while `r` reads each leaf's
    // buffer. The value mask is stored again before the buffer; OpenVDB skips it when reading
    // from a file and keeps the topology's, and so does this reader.
    let mut t = r.fork(children_at);
    let mut values = Vec::new();
    let mut skipped = 0;
    for &origin in &children {
        t.skip(12, "root child origin")?;
        let mut buffer = |origin: IVec3, mask: [u64; 8]| -> Result<()> {
            r.skip(64, "leaf value mask")?;
            if !visitor.wants_leaf(origin) {
                codec.skip_block(r, 512, &mask)?;
                skipped += 1;
                return Ok(());
            }
            codec.read_block(r, 512, &mask, &mut values)?;
            visitor.leaf(origin, &mask, &values)
        };
        read_internal(&mut t, codec, None, origin, 5, &mut buffer, &mut scratch)?;
    }
    Ok(skipped)
}

/// An internal node of `1 << (3 * log2)` slots (log2 = 5 or 4) at `origin`: its tiles to
/// `visitor` (none on the second walk), each leaf's origin and value mask to `leaf`.
fn read_internal(
    r: &mut Reader,
    codec: &Codec,
    mut visitor: Option<&mut dyn Visitor>,
    origin: IVec3,
    log2: u32,
    leaf: &mut dyn FnMut(IVec3, [u64; 8]) -> Result<()>,
    scratch: &mut Vec<f64>,
) -> Result<()> {
    let slots = 1usize << (3 * log2);
    let words = slots / 64;
    let child_log2 = if log2 == 5 { INTERNAL5_TILE_LOG2 } else { INTERNAL4_TILE_LOG2 };
    let child_mask = r.mask(words, "child mask")?;
    let value_mask = r.mask(words, "value mask")?;
    // The tile values go to the visitor; the second walk has none and skips them undecoded
    // (a corrupt block already failed the first walk).
    if visitor.is_some() {
        codec.read_block(r, slots, &value_mask, scratch)?;
    } else {
        codec.skip_block(r, slots, &value_mask)?;
    }
    let comps = codec.kind.comps;
    let slot_origin = |n: usize| {
        let m = (1usize << log2) - 1;
        let x = (n >> (2 * log2)) & m;
        let y = (n >> log2) & m;
        let z = n & m;
        origin + (IVec3::new(x as i32, y as i32, z as i32) << child_log2 as i32)
    };
    if let Some(visitor) = visitor.as_deref_mut() {
        for n in 0..slots {
            if bit(&child_mask, n) {
                continue;
            }
            let v = &scratch[n * comps..(n + 1) * comps];
            let active = bit(&value_mask, n);
            if active || v != codec.background.as_slice() {
                visitor.tile(slot_origin(n), child_log2, v, active)?;
            }
        }
    }
    let children: Vec<usize> = ones(&child_mask).collect();
    if log2 == 5 {
        // Each child needs at least its two 512-byte masks.
        if children.len() as u64 * 1024 > r.remaining() as u64 {
            return Err(r.err(format!("internal node claims {} children, more than the bytes left can hold", children.len())));
        }
        for n in children {
            // Reborrowed for the child (a trait object's lifetime shortens only by coercion).
            let v: Option<&mut dyn Visitor> = match &mut visitor {
                Some(v) => Some(&mut **v),
                None => None,
            };
            read_internal(r, codec, v, slot_origin(n), 4, leaf, scratch)?;
        }
    } else {
        if children.len() as u64 * 64 > r.remaining() as u64 {
            return Err(r.err(format!("internal node claims {} leaves, more than the bytes left can hold", children.len())));
        }
        for n in children {
            let m = r.mask(8, "leaf value mask")?;
            let mut mask = [0u64; 8];
            mask.copy_from_slice(&m);
            if let Some(v) = visitor.as_deref_mut().filter(|v| v.topology_only()) {
                v.wants_leaf(slot_origin(n));
            }
            leaf(slot_origin(n), mask)?;
        }
    }
    Ok(())
}
