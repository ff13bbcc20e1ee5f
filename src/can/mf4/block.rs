//! MDF 4 blocks (ASAM MCD-2 MDF 4.1, section 5): the 24-byte header (`##XX`, reserved, length,
//! link count), the links and the data section; reading one at a file offset with bounds checked,
//! and appending them to a file being built with their links patched afterwards; and the
//! identification block that starts every MDF file ([`MAGIC`], [`ID_BLOCK_LEN`]).

use super::error::Mf4Error;

/// The first 8 bytes of every MDF file.
pub const MAGIC: &[u8; 8] = b"MDF     ";

/// Whether `head` (the first bytes of a file) starts like an MDF file.
pub fn is_mdf(head: &[u8]) -> bool {
    head.starts_with(MAGIC)
}

/// Size of the identification block at the start of every MDF file.
pub(crate) const ID_BLOCK_LEN: u64 = 64;
/// Size of a block header: `##XX`, 4 reserved bytes, the length and the link count.
pub(crate) const HEADER_LEN: usize = 24;

/// One block read from the file: its type (`HD`, `DG`, …), links and data section.
#[derive(Debug, Clone)]
pub(crate) struct Block<'a> {
    pub kind: [u8; 2],
    pub links: Vec<u64>,
    pub data: &'a [u8],
}

impl Block<'_> {
    /// Link `i`, 0 (nil) when the block has fewer.
    pub fn link(&self, i: usize) -> u64 {
        self.links.get(i).copied().unwrap_or(0)
    }

    /// `n` bytes of the data section at `at`, or the error naming the block.
    pub fn bytes(&self, at: usize, n: usize) -> Result<&[u8], Mf4Error> {
        self.data.get(at..at + n).ok_or(Mf4Error::ShortBlock {
            kind: kind_text(self.kind),
            need: at + n,
            have: self.data.len(),
        })
    }

    pub fn u8(&self, at: usize) -> Result<u8, Mf4Error> {
        Ok(self.bytes(at, 1)?[0])
    }

    pub fn u16(&self, at: usize) -> Result<u16, Mf4Error> {
        Ok(u16::from_le_bytes(
            self.bytes(at, 2)?.try_into().unwrap_or([0; 2]),
        ))
    }

    pub fn u32(&self, at: usize) -> Result<u32, Mf4Error> {
        Ok(u32::from_le_bytes(
            self.bytes(at, 4)?.try_into().unwrap_or([0; 4]),
        ))
    }

    pub fn u64(&self, at: usize) -> Result<u64, Mf4Error> {
        Ok(u64::from_le_bytes(
            self.bytes(at, 8)?.try_into().unwrap_or([0; 8]),
        ))
    }

    pub fn f64(&self, at: usize) -> Result<f64, Mf4Error> {
        Ok(f64::from_bits(self.u64(at)?))
    }
}

/// A block type as text for messages.
pub(crate) fn kind_text(kind: [u8; 2]) -> String {
    String::from_utf8_lossy(&kind).into_owned()
}

/// The block at `at` (any type).
pub fn read(file: &[u8], at: u64) -> Result<Block<'_>, Mf4Error> {
    let start = usize::try_from(at).map_err(|_| Mf4Error::Link { at })?;
    let head = file
        .get(start..start.saturating_add(HEADER_LEN))
        .ok_or(Mf4Error::Link { at })?;
    if &head[..2] != b"##" {
        return Err(Mf4Error::NotABlock { at });
    }
    let kind = [head[2], head[3]];
    let len = u64::from_le_bytes(head[8..16].try_into().unwrap_or([0; 8]));
    let link_count = u64::from_le_bytes(head[16..24].try_into().unwrap_or([0; 8]));
    let links_len = link_count
        .checked_mul(8)
        .ok_or(Mf4Error::NotABlock { at })?;
    let end = at.checked_add(len).ok_or(Mf4Error::NotABlock { at })?;
    if len < HEADER_LEN as u64 + links_len || end > file.len() as u64 {
        return Err(Mf4Error::Truncated {
            kind: kind_text(kind),
            at,
        });
    }
    let links_end = start + HEADER_LEN + links_len as usize;
    let links = file[start + HEADER_LEN..links_end]
        .chunks_exact(8)
        .map(|c| u64::from_le_bytes(c.try_into().unwrap_or([0; 8])))
        .collect();
    Ok(Block {
        kind,
        links,
        data: &file[links_end..end as usize],
    })
}

/// The block at `at`, which must be of type `kind`.
pub fn expect<'a>(file: &'a [u8], at: u64, kind: &[u8; 2]) -> Result<Block<'a>, Mf4Error> {
    let b = read(file, at)?;
    if &b.kind != kind {
        return Err(Mf4Error::WrongBlock {
            at,
            expected: kind_text(*kind),
            found: kind_text(b.kind),
        });
    }
    Ok(b)
}

/// The text of a `TX` or `MD` block (up to its first NUL; empty for a nil link).
pub fn text(file: &[u8], at: u64) -> Result<String, Mf4Error> {
    if at == 0 {
        return Ok(String::new());
    }
    let b = read(file, at)?;
    let end = b.data.iter().position(|c| *c == 0).unwrap_or(b.data.len());
    Ok(String::from_utf8_lossy(&b.data[..end]).into_owned())
}

/// A file being built in memory: blocks appended at 8-byte aligned offsets, links patched once
/// their targets are known.
#[derive(Debug, Default)]
pub struct Builder {
    pub buf: Vec<u8>,
}

impl Builder {
    /// Appends a block with `links` and `data` (padded to 8 bytes); its offset in the file.
    pub fn add(&mut self, kind: &[u8; 2], links: &[u64], data: &[u8]) -> u64 {
        self.pad();
        let at = self.buf.len() as u64;
        self.buf.extend_from_slice(&block_header(
            kind,
            links.len(),
            data.len().next_multiple_of(8) as u64,
        ));
        for l in links {
            self.buf.extend_from_slice(&l.to_le_bytes());
        }
        self.buf.extend_from_slice(data);
        self.pad();
        at
    }

    /// A `TX` block holding `s`; nil (0) for an empty string.
    pub fn text(&mut self, s: &str) -> u64 {
        if s.is_empty() {
            return 0;
        }
        self.add(b"TX", &[], &nul_terminated(s))
    }

    /// An `MD` block holding the XML `s`.
    pub fn xml(&mut self, s: &str) -> u64 {
        self.add(b"MD", &[], &nul_terminated(s))
    }

    /// Sets link `i` of the block at `block` to `target`.
    pub fn set_link(&mut self, block: u64, i: usize, target: u64) {
        let at = block as usize + HEADER_LEN + 8 * i;
        self.buf[at..at + 8].copy_from_slice(&target.to_le_bytes());
    }

    fn pad(&mut self) {
        let n = self.buf.len().next_multiple_of(8);
        self.buf.resize(n, 0);
    }
}

/// The header of a block with `links` links and `data_len` bytes of data.
pub(crate) fn block_header(kind: &[u8; 2], links: usize, data_len: u64) -> [u8; HEADER_LEN] {
    let mut h = [0u8; HEADER_LEN];
    h[..2].copy_from_slice(b"##");
    h[2..4].copy_from_slice(kind);
    let len = HEADER_LEN as u64 + 8 * links as u64 + data_len;
    h[8..16].copy_from_slice(&len.to_le_bytes());
    h[16..24].copy_from_slice(&(links as u64).to_le_bytes());
    h
}

fn nul_terminated(s: &str) -> Vec<u8> {
    let mut v = s.as_bytes().to_vec();
    v.push(0);
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_built_block_reads_back_with_its_links_and_data() {
        let mut b = Builder::default();
        b.buf.resize(ID_BLOCK_LEN as usize, 0);
        let tx = b.text("vcan0");
        let dg = b.add(b"DG", &[0, 0, 0, 0], &[1, 0, 0, 0, 0, 0, 0, 0]);
        b.set_link(dg, 2, tx);
        let blk = expect(&b.buf, dg, b"DG").unwrap();
        assert_eq!(blk.links, vec![0, 0, tx, 0]);
        assert_eq!(blk.u8(0).unwrap(), 1);
        assert_eq!(text(&b.buf, tx).unwrap(), "vcan0");
        assert_eq!(tx % 8, 0);
        assert!(matches!(
            expect(&b.buf, dg, b"CG"),
            Err(Mf4Error::WrongBlock { .. })
        ));
        // A length past the end of the file is a truncation, not a panic.
        let cut = &b.buf[..b.buf.len() - 8];
        assert!(matches!(read(cut, dg), Err(Mf4Error::Truncated { .. })));
        assert!(matches!(read(&b.buf, 3), Err(Mf4Error::NotABlock { .. })));
        assert!(matches!(read(&b.buf, 1 << 40), Err(Mf4Error::Link { .. })));
    }
}
