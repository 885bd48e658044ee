//! What `render` hands to people and other tools: an animated GIF of the rendered path, and
//! the per-frame PLYs as one `.zip` that a splat viewer plays as an animation.
//!
//! The zip is what brush (ArthurBrussee/brush) reads as a sequence: it streams the archive
//! entry by entry from the local headers (so every entry is stored, with its CRC and sizes in
//! the local header and no data descriptor), keeps the entries whose name ends in `.ply`, sorts
//! them by natural (alphanumeric) order and plays them as frames. So the archive holds only
//! `frame_NNNN.ply` (the canonical model would sort first and become frame 0), zero-padded.

use std::io::Write;
use std::path::{Path, PathBuf};

use image::RgbImage;

use crate::error::{Error, Result};

/// Writes `frames` (all one size) as a looping GIF at `fps` frames per second.
pub fn write_gif(path: &Path, frames: &[RgbImage], fps: u32) -> Result<()> {
    let Some(first) = frames.first() else {
        return Err(Error::Invalid(format!(
            "{}: no frames to animate",
            path.display()
        )));
    };
    if fps == 0 || fps > 100 {
        return Err(Error::Invalid(format!(
            "--fps {fps}: expected 1 to 100 (GIF delays are hundredths of a second)"
        )));
    }
    if let Some((i, f)) = frames
        .iter()
        .enumerate()
        .find(|(_, f)| f.dimensions() != first.dimensions())
    {
        return Err(Error::Invalid(format!(
            "{}: frame {i} is {:?}, frame 0 is {:?}; a GIF's frames share one size",
            path.display(),
            f.dimensions(),
            first.dimensions()
        )));
    }
    if let Some(d) = path.parent() {
        std::fs::create_dir_all(d).map_err(Error::io(d))?;
    }
    let tmp = path.with_extension("gif.tmp");
    let file = std::fs::File::create(&tmp).map_err(Error::io(&tmp))?;
    let mut enc = image::codecs::gif::GifEncoder::new_with_speed(std::io::BufWriter::new(file), 10);
    let gif_err = |e: image::ImageError| Error::Invalid(format!("{}: {e}", path.display()));
    enc.set_repeat(image::codecs::gif::Repeat::Infinite)
        .map_err(gif_err)?;
    let delay = image::Delay::from_numer_denom_ms(1000, fps);
    for f in frames {
        let rgba = image::DynamicImage::ImageRgb8(f.clone()).to_rgba8();
        enc.encode_frame(image::Frame::from_parts(rgba, 0, 0, delay))
            .map_err(gif_err)?;
    }
    drop(enc);
    std::fs::rename(&tmp, path).map_err(Error::io(path))
}

/// CRC-32 (IEEE 802.3, reflected), as zip stores it.
pub fn crc32(bytes: &[u8]) -> u32 {
    static TABLE: std::sync::OnceLock<[u32; 256]> = std::sync::OnceLock::new();
    let t = TABLE.get_or_init(|| {
        let mut t = [0u32; 256];
        for (i, e) in t.iter_mut().enumerate() {
            let mut c = i as u32;
            for _ in 0..8 {
                c = if c & 1 != 0 {
                    0xEDB8_8320 ^ (c >> 1)
                } else {
                    c >> 1
                };
            }
            *e = c;
        }
        t
    });
    !bytes.iter().fold(!0u32, |c, &b| {
        t[((c ^ b as u32) & 0xff) as usize] ^ (c >> 8)
    })
}

/// Writes the files `entries` (name inside the archive, file on disk) as a stored zip. Sizes
/// past zip's 32-bit fields (4 GiB) are refused rather than written as a broken archive.
pub fn write_stored_zip(path: &Path, entries: &[(String, PathBuf)]) -> Result<()> {
    let tmp = path.with_extension("zip.tmp");
    let file = std::fs::File::create(&tmp).map_err(Error::io(&tmp))?;
    let mut w = std::io::BufWriter::new(file);
    let mut central = Vec::new();
    let mut offset: u64 = 0;
    // 1980-01-01 00:00 in DOS time: the archive does not depend on the clock.
    let (dos_time, dos_date) = (0u16, (1 << 5) | 1u16);
    let too_big = |what: &str| {
        Error::Invalid(format!(
            "{}: {what} passes 4 GiB, which a zip without zip64 cannot hold; render fewer \
             frames or a smaller model",
            path.display()
        ))
    };
    for (name, src) in entries {
        let data = std::fs::read(src).map_err(Error::io(src))?;
        let size = u32::try_from(data.len()).map_err(|_| too_big(name))?;
        let at = u32::try_from(offset).map_err(|_| too_big("the archive"))?;
        let crc = crc32(&data);
        let n = name.as_bytes();
        let mut local = Vec::with_capacity(30 + n.len());
        local.extend(0x0403_4b50u32.to_le_bytes()); // local file header
        local.extend(20u16.to_le_bytes()); // version needed: 2.0
        local.extend(0u16.to_le_bytes()); // flags: no data descriptor
        local.extend(0u16.to_le_bytes()); // method: stored
        local.extend(dos_time.to_le_bytes());
        local.extend(dos_date.to_le_bytes());
        local.extend(crc.to_le_bytes());
        local.extend(size.to_le_bytes()); // compressed
        local.extend(size.to_le_bytes()); // uncompressed
        local.extend((n.len() as u16).to_le_bytes());
        local.extend(0u16.to_le_bytes()); // extra length
        local.extend(n);
        w.write_all(&local).map_err(Error::io(&tmp))?;
        w.write_all(&data).map_err(Error::io(&tmp))?;
        let mut c = Vec::with_capacity(46 + n.len());
        c.extend(0x0201_4b50u32.to_le_bytes()); // central directory header
        c.extend(20u16.to_le_bytes()); // made by: 2.0, MS-DOS attributes
        c.extend(20u16.to_le_bytes());
        c.extend(0u16.to_le_bytes());
        c.extend(0u16.to_le_bytes());
        c.extend(dos_time.to_le_bytes());
        c.extend(dos_date.to_le_bytes());
        c.extend(crc.to_le_bytes());
        c.extend(size.to_le_bytes());
        c.extend(size.to_le_bytes());
        c.extend((n.len() as u16).to_le_bytes());
        c.extend([0u8; 8]); // extra, comment, disk start, internal attributes
        c.extend(0u32.to_le_bytes()); // external attributes
        c.extend(at.to_le_bytes());
        c.extend(n);
        central.extend(c);
        offset += local.len() as u64 + data.len() as u64;
    }
    let cd_at = u32::try_from(offset).map_err(|_| too_big("the archive"))?;
    let count = u16::try_from(entries.len())
        .map_err(|_| Error::Invalid(format!("{}: more than 65535 frames", path.display())))?;
    w.write_all(&central).map_err(Error::io(&tmp))?;
    let mut end = Vec::with_capacity(22);
    end.extend(0x0605_4b50u32.to_le_bytes()); // end of central directory
    end.extend([0u8; 4]); // this disk, central directory's disk
    end.extend(count.to_le_bytes());
    end.extend(count.to_le_bytes());
    end.extend((central.len() as u32).to_le_bytes());
    end.extend(cd_at.to_le_bytes());
    end.extend(0u16.to_le_bytes()); // comment length
    w.write_all(&end).map_err(Error::io(&tmp))?;
    w.into_inner()
        .map_err(|e| Error::io(&tmp)(e.into_error()))?
        .sync_all()
        .map_err(Error::io(&tmp))?;
    std::fs::rename(&tmp, path).map_err(Error::io(path))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32_matches_the_standard_check_value() {
        // The CRC-32 catalogue's check value for "123456789".
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
    }
}
