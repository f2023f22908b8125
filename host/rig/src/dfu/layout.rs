//! The DfuSe memory layout string an STM32 bootloader names its flash interface with, e.g.
//! `@Internal Flash  /0x08000000/04*016Kg,01*064Kg,03*128Kg` (STM32F411: four 16 KiB, one
//! 64 KiB and three 128 KiB sectors). Each group is `COUNT*SIZE` with a unit (` `, `K`, `M`)
//! and a type letter whose bits (`letter − 'a' + 1`) say readable (1), erasable (2),
//! writable (4).
//!
//! Contract: [`parse`] returns the sectors of the first region in address order, or an error
//! quoting the string; only the internal flash region is accepted for firmware.

/// One erasable unit of flash.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Sector {
    /// First address.
    pub start: u32,
    /// Size, bytes.
    pub size: u32,
    /// Whether it can be erased and written.
    pub writable: bool,
}

/// A parsed layout: the region's name and its sectors.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MemoryLayout {
    /// Region name (`Internal Flash`).
    pub name: String,
    /// Sectors in address order.
    pub sectors: Vec<Sector>,
}

impl MemoryLayout {
    /// First address of the region.
    pub fn start(&self) -> u32 {
        self.sectors.first().map_or(0, |s| s.start)
    }

    /// One past the last address.
    pub fn end(&self) -> u64 {
        self.sectors
            .last()
            .map_or(0, |s| u64::from(s.start) + u64::from(s.size))
    }

    /// The sectors overlapping `[start, start + len)`.
    pub fn sectors_for(&self, start: u32, len: u32) -> Vec<Sector> {
        let end = u64::from(start) + u64::from(len);
        self.sectors
            .iter()
            .filter(|s| {
                u64::from(s.start) < end
                    && u64::from(s.start) + u64::from(s.size) > u64::from(start)
            })
            .copied()
            .collect()
    }
}

/// Why a layout string does not parse.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("memory layout '{text}' does not parse: {why}")]
pub struct LayoutError {
    /// The string.
    pub text: String,
    /// What is wrong.
    pub why: String,
}

/// Parses a DfuSe layout string.
pub fn parse(text: &str) -> Result<MemoryLayout, LayoutError> {
    let err = |why: &str| LayoutError {
        text: text.to_string(),
        why: why.to_string(),
    };
    let body = text
        .strip_prefix('@')
        .ok_or_else(|| err("no leading '@'"))?;
    let mut parts = body.split('/');
    let name = parts.next().unwrap_or("").trim().to_string();
    let addr = parts.next().ok_or_else(|| err("no start address"))?.trim();
    let start = u32::from_str_radix(
        addr.strip_prefix("0x")
            .or_else(|| addr.strip_prefix("0X"))
            .ok_or_else(|| err("start address is not 0x…"))?,
        16,
    )
    .map_err(|_| err("start address is not hexadecimal"))?;
    let groups = parts.next().ok_or_else(|| err("no sector list"))?;
    let mut sectors = Vec::new();
    let mut at = u64::from(start);
    for g in groups.split(',') {
        let g = g.trim();
        let (count, rest) = g.split_once('*').ok_or_else(|| err("a group lacks '*'"))?;
        let count: u32 = count.trim().parse().map_err(|_| err("bad sector count"))?;
        let kind = rest.chars().last().ok_or_else(|| err("empty group"))?;
        let rest = &rest[..rest.len() - kind.len_utf8()];
        let (digits, mult) = match rest.chars().last() {
            Some('K') => (&rest[..rest.len() - 1], 1024),
            Some('M') => (&rest[..rest.len() - 1], 1024 * 1024),
            Some(' ') | Some('B') => (&rest[..rest.len() - 1], 1),
            _ => (rest, 1),
        };
        let size: u32 = digits
            .trim()
            .parse::<u32>()
            .map_err(|_| err("bad sector size"))?
            .checked_mul(mult)
            .ok_or_else(|| err("sector size overflows"))?;
        if !('a'..='g').contains(&kind) || size == 0 || count == 0 {
            return Err(err("bad sector type, size or count"));
        }
        let bits = kind as u32 - 'a' as u32 + 1;
        for _ in 0..count {
            let s = u32::try_from(at).map_err(|_| err("layout runs past 4 GiB"))?;
            sectors.push(Sector {
                start: s,
                size,
                writable: bits & 6 == 6,
            });
            at += u64::from(size);
        }
    }
    if sectors.is_empty() {
        return Err(err("no sectors"));
    }
    Ok(MemoryLayout { name, sectors })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stm32f411_layout() {
        let l = parse("@Internal Flash  /0x08000000/04*016Kg,01*064Kg,03*128Kg").expect("parses");
        assert_eq!(l.name, "Internal Flash");
        assert_eq!(l.sectors.len(), 8);
        assert_eq!(l.start(), 0x0800_0000);
        assert_eq!(l.end(), 0x0808_0000);
        assert_eq!(
            l.sectors[4],
            Sector {
                start: 0x0801_0000,
                size: 65536,
                writable: true
            }
        );
        // 40 KiB from the start: the first three 16 KiB sectors
        assert_eq!(l.sectors_for(0x0800_0000, 40 * 1024).len(), 3);
        let bad = parse("Internal Flash/0x0800/1*1Kg").expect_err("no @");
        assert!(bad.to_string().contains("Internal Flash/0x0800"), "{bad}");
        assert!(parse("@Option Bytes  /0x1FFFC000/01*016 e").is_ok());
    }
}
