//! Image I/O helpers: frames on disk (PNG 8/16-bit, JPEG, binary PGM 8/16-bit) to a grey buffer,
//! PNG output, and image lists given as files or directories ([`expand_image_paths`]).
//!
//! Every error is an [`omni_formats::Error`] naming the file, so a tool can print it as is:
//! `frames/000012.png: truncated or corrupt image: …`.
//!
//! ```no_run
//! let img = omni_vision::image_io::load_gray(std::path::Path::new("frames/000000.png")).unwrap();
//! println!("{}x{} px, {}-bit, max {}", img.width, img.height, img.bit_depth, img.max_value());
//! ```

use crate::colour::{ColourSpec, RgbImage};
use omni_formats::Error;
use std::path::{Path, PathBuf};

/// File name extensions (lower case) that [`expand_image_paths`] takes from a directory.
pub const IMAGE_EXTENSIONS: [&str; 7] = ["png", "jpg", "jpeg", "tif", "tiff", "bmp", "pgm"];

/// The image files of a command line: files as given, each directory replaced by its files whose
/// extension is one of [`IMAGE_EXTENSIONS`] (any case), sorted by path. A directory without one
/// is an error naming it (`boards: no images in directory`).
pub fn expand_image_paths(paths: &[PathBuf]) -> Result<Vec<PathBuf>, Error> {
    let mut out = Vec::new();
    for p in paths {
        if p.is_dir() {
            let name = p.display().to_string();
            let mut files: Vec<PathBuf> = std::fs::read_dir(p)
                .map_err(|e| Error::io(name.as_str(), &e))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|f| {
                    let ext = f.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
                    IMAGE_EXTENSIONS.contains(&ext.as_str())
                })
                .collect();
            files.sort();
            if files.is_empty() {
                return Err(Error::new(name, "", "no images in directory"));
            }
            out.extend(files);
        } else {
            out.push(p.clone());
        }
    }
    Ok(out)
}

/// A single-channel image. Samples are stored as `u16` whatever the file's depth; `bit_depth`
/// says which range they use (8 → 0–255, 16 → 0–65535). Row-major, `data[y * width + x]`,
/// pixel (0, 0) is the top-left one.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GrayImage {
    pub width: u32,
    pub height: u32,
    /// 8 or 16.
    pub bit_depth: u8,
    pub data: Vec<u16>,
}

impl GrayImage {
    /// An all-zero image.
    pub fn new(width: u32, height: u32, bit_depth: u8) -> Self {
        GrayImage { width, height, bit_depth, data: vec![0; width as usize * height as usize] }
    }

    /// The largest value a sample can take (255 or 65535): the saturation level.
    pub fn max_value(&self) -> u16 {
        if self.bit_depth <= 8 { 255 } else { u16::MAX }
    }

    /// The sample at column `x`, row `y` (panics outside the image).
    pub fn get(&self, x: u32, y: u32) -> u16 {
        self.data[y as usize * self.width as usize + x as usize]
    }

    /// The samples as `f32` in the file's own units (no rescaling).
    pub fn to_f32(&self) -> Vec<f32> {
        self.data.iter().map(|&v| v as f32).collect()
    }

    /// The samples as `u8` (16-bit images are scaled down by 257); for 8-bit pipelines.
    pub fn to_u8(&self) -> Vec<u8> {
        if self.bit_depth <= 8 {
            self.data.iter().map(|&v| v.min(255) as u8).collect()
        } else {
            self.data.iter().map(|&v| (v / 257) as u8).collect()
        }
    }

    /// Subtracts `other` (e.g. a laser-off frame) sample by sample, clamping at 0.
    /// The error message says how the sizes differ.
    pub fn subtract_saturating(&mut self, other: &GrayImage) -> Result<(), String> {
        if (self.width, self.height) != (other.width, other.height) {
            return Err(format!(
                "size {}x{} differs from the frame's {}x{}",
                other.width, other.height, self.width, self.height
            ));
        }
        for (a, &b) in self.data.iter_mut().zip(&other.data) {
            *a = a.saturating_sub(b);
        }
        Ok(())
    }
}

/// Loads a PNG (8- or 16-bit, grey or colour), JPEG or binary PGM (`P5`, 8- or 16-bit, the
/// uncompressed format `omni-trigger` can capture into) file as a grey image. Colour images are
/// converted to luma. Missing, truncated, corrupt and non-image files give an error naming the
/// file.
pub fn load_gray(path: &Path) -> Result<GrayImage, Error> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path.display().to_string(), &e))?;
    decode_gray(&bytes, &path.display().to_string())
}

/// Decodes an in-memory PNG/JPEG/PGM file; `name` is used in error messages.
pub fn decode_gray(bytes: &[u8], name: &str) -> Result<GrayImage, Error> {
    Ok(from_dynamic(decode_checked(bytes, name)?))
}

/// A grey frame as decoded: an 8-bit frame keeps its bytes, which the stripe detector reads
/// directly (widening them to 16 bits costs a pass and makes the detection about a fifth
/// slower); any other frame as a [`GrayImage`], as [`load_gray`] reads it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum DecodedGray {
    Eight { width: u32, height: u32, data: Vec<u8> },
    Wide(GrayImage),
}

impl DecodedGray {
    /// An image as the detector reads it: an 8-bit one as its bytes.
    pub fn from_gray(img: GrayImage) -> Self {
        match img.bit_depth {
            8 => DecodedGray::Eight {
                width: img.width,
                height: img.height,
                data: img.data.iter().map(|&v| v.min(255) as u8).collect(),
            },
            _ => DecodedGray::Wide(img),
        }
    }

    /// Width and height (px).
    pub fn size(&self) -> (u32, u32) {
        match self {
            DecodedGray::Eight { width, height, .. } => (*width, *height),
            DecodedGray::Wide(img) => (img.width, img.height),
        }
    }

    /// 8 or 16.
    pub fn bit_depth(&self) -> u8 {
        match self {
            DecodedGray::Eight { .. } => 8,
            DecodedGray::Wide(img) => img.bit_depth,
        }
    }

    /// Subtracts `other` (same size) sample by sample, clamping at 0, as
    /// [`GrayImage::subtract_saturating`] does, in the frame's own sample type.
    pub fn subtract_saturating(&mut self, other: &DecodedGray) -> Result<(), String> {
        let ((w, h), (ow, oh)) = (self.size(), other.size());
        if (w, h) != (ow, oh) {
            return Err(format!("size {ow}x{oh} differs from the frame's {w}x{h}"));
        }
        match (self, other) {
            (DecodedGray::Eight { data, .. }, DecodedGray::Eight { data: off, .. }) => {
                data.iter_mut().zip(off).for_each(|(a, &b)| *a = a.saturating_sub(b));
            }
            (DecodedGray::Eight { data, .. }, DecodedGray::Wide(off)) => {
                data.iter_mut().zip(&off.data).for_each(|(a, &b)| *a = u16::from(*a).saturating_sub(b) as u8);
            }
            (DecodedGray::Wide(img), DecodedGray::Eight { data: off, .. }) => {
                img.data.iter_mut().zip(off).for_each(|(a, &b)| *a = a.saturating_sub(u16::from(b)));
            }
            (DecodedGray::Wide(img), DecodedGray::Wide(off)) => img.subtract_saturating(off)?,
        }
        Ok(())
    }

    /// The frame as a [`GrayImage`] (an 8-bit frame's bytes widened).
    pub fn into_gray(self) -> GrayImage {
        match self {
            DecodedGray::Eight { width, height, data } => {
                GrayImage { width, height, bit_depth: 8, data: data.into_iter().map(u16::from).collect() }
            }
            DecodedGray::Wide(img) => img,
        }
    }
}

/// [`load_gray`], keeping an 8-bit grey frame's bytes as they are. A plain 8-bit binary PGM
/// (what `omni-trigger` captures) is read straight into the frame's buffer: one copy out of the
/// page cache, where the decoder adds a zeroed buffer and a second copy.
pub fn load_gray_decoded(path: &Path) -> Result<DecodedGray, Error> {
    let bytes = match read_frame_file(path)? {
        FrameFile::PlainPgm8(frame) => return Ok(frame),
        FrameFile::Encoded(bytes) => bytes,
    };
    Ok(match decode_checked(&bytes, &path.display().to_string())? {
        image::DynamicImage::ImageLuma8(g) => {
            DecodedGray::Eight { width: g.width(), height: g.height(), data: g.into_raw() }
        }
        other => DecodedGray::Wide(from_dynamic(other)),
    })
}

/// A frame file as read once: a plain 8-bit binary PGM's samples, or the file's bytes for the
/// decoder.
enum FrameFile {
    PlainPgm8(DecodedGray),
    Encoded(Vec<u8>),
}

/// Reads the frame file at `path` once. An 8-bit binary PGM without comments whose file is
/// exactly its header and width × height samples goes straight into the frame's buffer;
/// anything else (a file that changed while it was read included) is left to the decoder, to
/// read or to name the fault of.
fn read_frame_file(path: &Path) -> Result<FrameFile, Error> {
    use std::io::Read;
    /// Longer than any plain PGM header of a frame within the size limit.
    const HEAD_BYTES: u64 = 64;
    let io = |e: std::io::Error| Error::io(path.display().to_string(), &e);
    let mut file = std::fs::File::open(path).map_err(io)?;
    let size = file.metadata().map_err(io)?.len();
    let mut head = Vec::with_capacity(HEAD_BYTES as usize);
    (&mut file).take(HEAD_BYTES).read_to_end(&mut head).map_err(io)?;
    let max = u64::from(omni_model::limits::MAX_IMAGE_SIDE_PX);
    let plain = plain_pgm8_header(&head).filter(|&(w, h, header)| {
        (1..=max).contains(&u64::from(w))
            && (1..=max).contains(&u64::from(h))
            && size == header as u64 + u64::from(w) * u64::from(h)
    });
    let Some((width, height, header)) = plain else {
        file.read_to_end(&mut head).map_err(io)?;
        return Ok(FrameFile::Encoded(head));
    };
    let samples = width as usize * height as usize;
    let mut data = Vec::with_capacity(samples);
    data.extend_from_slice(&head[header..]);
    file.read_to_end(&mut data).map_err(io)?;
    if data.len() == samples {
        return Ok(FrameFile::PlainPgm8(DecodedGray::Eight { width, height, data }));
    }
    head.truncate(header);
    head.extend(data);
    Ok(FrameFile::Encoded(head))
}

/// Width, height and length (bytes) of a binary PGM header (`P5`, width, height and maxval as
/// decimal text after whitespace, one whitespace byte after the maxval) whose maxval is 255
/// and which holds no comment.
fn plain_pgm8_header(bytes: &[u8]) -> Option<(u32, u32, usize)> {
    let mut at = b"P5".len();
    if !bytes.starts_with(b"P5") {
        return None;
    }
    let mut fields = [0u32; 3];
    for field in &mut fields {
        let spaces = bytes[at..].iter().take_while(|b| b.is_ascii_whitespace()).count();
        let digits = bytes[at + spaces..].iter().take_while(|b| b.is_ascii_digit()).count();
        if spaces == 0 || digits == 0 || digits > 9 {
            return None;
        }
        at += spaces;
        *field = std::str::from_utf8(&bytes[at..at + digits]).ok()?.parse().ok()?;
        at += digits;
    }
    let [width, height, maxval] = fields;
    (maxval == 255 && bytes.get(at)?.is_ascii_whitespace()).then_some((width, height, at + 1))
}

/// Whether the image file at `path` holds colour (from its header alone); `None` if it cannot be
/// read or recognised (the frame's own loading reports that).
pub fn is_colour_file(path: &Path) -> Option<bool> {
    use image::ImageDecoder;
    let reader = image::ImageReader::open(path).ok()?.with_guessed_format().ok()?;
    Some(reader.into_decoder().ok()?.color_type().has_color())
}

/// Loads a frame as the stripe detector reads it: [`load_gray`] for [`ColourSpec::default`];
/// otherwise the channel or laser contrast of a colour frame, or of a raw Bayer mosaic
/// demosaiced first (`crate::colour`). A grey frame given a colour reading, a colour frame given
/// a Bayer order, and a mosaic with odd sides are errors naming the file and the option.
pub fn load_frame_channel(path: &Path, spec: &ColourSpec) -> Result<GrayImage, Error> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path.display().to_string(), &e))?;
    decode_frame_channel(&bytes, &path.display().to_string(), spec)
}

/// [`load_frame_channel`] of an in-memory PNG/JPEG/PGM file; `name` is used in error messages.
pub fn decode_frame_channel(bytes: &[u8], name: &str, spec: &ColourSpec) -> Result<GrayImage, Error> {
    if *spec == ColourSpec::default() {
        return decode_gray(bytes, name);
    }
    Ok(decode_channel(decode_checked(bytes, name)?, name, spec)?.into_gray())
}

/// [`load_frame_channel`] and, where `also` is given, that channel of the same frame read the
/// same way (a laser colour's own channel beside its contrast), the file read and decoded once.
pub fn load_frame_channels(
    path: &Path,
    spec: &ColourSpec,
    also: Option<crate::colour::Channel>,
) -> Result<(GrayImage, Option<GrayImage>), Error> {
    let name = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| Error::io(name.clone(), &e))?;
    let Some(channel) = also else { return Ok((decode_frame_channel(&bytes, &name, spec)?, None)) };
    let other = ColourSpec { channel, ..*spec };
    if *spec == ColourSpec::default() || other == ColourSpec::default() {
        return Ok((decode_frame_channel(&bytes, &name, spec)?, Some(decode_frame_channel(&bytes, &name, &other)?)));
    }
    let dynamic = decode_checked(&bytes, &name)?;
    let first = decode_channel(dynamic.clone(), &name, spec)?.into_gray();
    Ok((first, Some(decode_channel(dynamic, &name, &other)?.into_gray())))
}

/// [`load_frame_channel`], keeping the bytes of a channel read from an 8-bit colour frame as
/// [`load_gray_decoded`] keeps an 8-bit grey frame's.
pub fn load_frame_channel_decoded(path: &Path, spec: &ColourSpec) -> Result<DecodedGray, Error> {
    if *spec == ColourSpec::default() {
        return load_gray_decoded(path);
    }
    let name = path.display().to_string();
    let bytes = std::fs::read(path).map_err(|e| Error::io(name.clone(), &e))?;
    decode_channel(decode_checked(&bytes, &name)?, &name, spec)
}

/// The grey frame `spec` (not the default) reads from a decoded frame file `name`.
fn decode_channel(dynamic: image::DynamicImage, name: &str, spec: &ColourSpec) -> Result<DecodedGray, Error> {
    let grey = !dynamic.color().has_color();
    let rgb = match spec.bayer {
        Some(order) => {
            if !grey {
                return Err(Error::new(
                    name,
                    "",
                    format!("{}: the frame is a colour image, not a raw Bayer mosaic (drop --bayer)", spec.describe()),
                ));
            }
            let sites = if spec.sites { " --bayer-sites" } else { "" };
            spec.read_mosaic(&from_dynamic(dynamic), order)
                .map_err(|m| Error::new(name, "", format!("--bayer {}{sites}: {m}", order.name())))?
        }
        None => {
            if grey {
                return Err(Error::new(
                    name,
                    "",
                    format!(
                        "{}: the frame is grey, with no colour to read (a raw Bayer mosaic needs --bayer ORDER)",
                        spec.describe()
                    ),
                ));
            }
            // 8-bit colour, the common case, in one pass from the decoded samples.
            let (width, height) = (dynamic.width(), dynamic.height());
            let bytes = |samples: &[u8], stride| crate::colour::channel_bytes_of_rgb8(samples, stride, spec.channel);
            match &dynamic {
                image::DynamicImage::ImageRgb8(buf) => {
                    return Ok(DecodedGray::Eight { width, height, data: bytes(buf.as_raw(), 3) });
                }
                image::DynamicImage::ImageRgba8(buf) => {
                    return Ok(DecodedGray::Eight { width, height, data: bytes(buf.as_raw(), 4) });
                }
                _ => rgb_of(dynamic),
            }
        }
    };
    Ok(DecodedGray::Wide(rgb.channel(spec.channel)))
}

/// A colour frame's samples as RGB in its own depth (8 or 16 bit; alpha dropped).
fn rgb_of(dynamic: image::DynamicImage) -> RgbImage {
    use image::DynamicImage as D;
    let (width, height) = (dynamic.width(), dynamic.height());
    match dynamic {
        D::ImageRgb16(_) | D::ImageRgba16(_) | D::ImageLumaA16(_) | D::ImageLuma16(_) => {
            let data = dynamic.to_rgb16().into_raw().chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
            RgbImage { width, height, bit_depth: 16, data }
        }
        other => {
            let data =
                other.to_rgb8().into_raw().chunks_exact(3).map(|c| [c[0] as u16, c[1] as u16, c[2] as u16]).collect();
            RgbImage { width, height, bit_depth: 8, data }
        }
    }
}

/// Loads a PNG or JPEG file as it is (colour kept), with the checks of [`load_gray`].
pub fn load_dynamic(path: &Path) -> Result<image::DynamicImage, Error> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path.display().to_string(), &e))?;
    decode_checked(&bytes, &path.display().to_string())
}

/// Decodes a PNG/JPEG file, refusing empty files, truncated JPEGs (no end-of-image marker)
/// and sizes beyond [`omni_model::limits::MAX_IMAGE_SIDE_PX`] before any pixel is allocated.
fn decode_checked(bytes: &[u8], name: &str) -> Result<image::DynamicImage, Error> {
    if bytes.is_empty() {
        return Err(Error::new(name, "", "empty file, not an image"));
    }
    let format = image::guess_format(bytes)
        .map_err(|_| Error::new(name, "", "not a PNG, JPEG or PGM image (unrecognised file signature)"))?;
    if format == image::ImageFormat::Jpeg && !jpeg_has_end(bytes) {
        // The JPEG decoder fills a cut-off scan with grey and reports success.
        return Err(Error::new(name, "", "truncated JPEG: no end-of-image marker (FF D9) at the end of the file"));
    }
    let max = omni_model::limits::MAX_IMAGE_SIDE_PX;
    let reader = || image::ImageReader::with_format(std::io::Cursor::new(bytes), format);
    let (w, h) =
        reader().into_dimensions().map_err(|e| Error::new(name, "", format!("truncated or corrupt image: {e}")))?;
    if w > max || h > max {
        return Err(Error::new(name, "", format!("image size {w}x{h} exceeds the limit of {max} px per side")));
    }
    if w == 0 || h == 0 {
        return Err(Error::new(name, "", format!("image size {w}x{h}: no pixels")));
    }
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(max);
    limits.max_image_height = Some(max);
    let mut decoder = reader();
    decoder.limits(limits);
    decoder.decode().map_err(|e| Error::new(name, "", format!("truncated or corrupt image: {e}")))
}

/// Whether a JPEG file ends with its end-of-image marker (trailing zero padding, as some
/// cameras write, is allowed).
fn jpeg_has_end(bytes: &[u8]) -> bool {
    let end = bytes.iter().rposition(|&b| b != 0).map_or(0, |k| k + 1);
    bytes[..end].ends_with(&[0xFF, 0xD9])
}

fn from_dynamic(dynamic: image::DynamicImage) -> GrayImage {
    use image::DynamicImage as D;
    let (width, height) = (dynamic.width(), dynamic.height());
    match dynamic {
        D::ImageLuma8(g) => {
            GrayImage { width, height, bit_depth: 8, data: g.into_raw().into_iter().map(u16::from).collect() }
        }
        D::ImageLuma16(g) => GrayImage { width, height, bit_depth: 16, data: g.into_raw() },
        D::ImageRgb16(_) | D::ImageRgba16(_) | D::ImageLumaA16(_) => {
            GrayImage { width, height, bit_depth: 16, data: dynamic.to_luma16().into_raw() }
        }
        other => {
            let g = other.to_luma8();
            GrayImage { width, height, bit_depth: 8, data: g.into_raw().into_iter().map(u16::from).collect() }
        }
    }
}

/// Writes an RGB8 image (`rgb.len() == 3 * width * height`) as PNG, atomically.
pub fn write_rgb_png(path: &Path, width: u32, height: u32, rgb: &[u8]) -> Result<(), Error> {
    omni_formats::io::write_atomic(path, |w| {
        let mut buf = std::io::Cursor::new(Vec::new());
        image::write_buffer_with_format(
            &mut buf,
            rgb,
            width,
            height,
            image::ExtendedColorType::Rgb8,
            image::ImageFormat::Png,
        )
        .map_err(std::io::Error::other)?;
        w.write_all(buf.get_ref())
    })
}

/// Writes a grey image as PNG (8- or 16-bit as its `bit_depth` says), atomically.
pub fn write_gray_png(path: &Path, img: &GrayImage) -> Result<(), Error> {
    omni_formats::io::write_atomic(path, |w| {
        use image::ExtendedColorType::{L8, L16};
        let mut buf = Vec::new();
        omni_formats::png::write_samples_png(&mut buf, &img.data, img.bit_depth, (img.width, img.height), [L8, L16])
            .map_err(std::io::Error::other)?;
        w.write_all(&buf)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn directories_expand_to_their_images_sorted_files_stay_as_given() {
        let dir = tempfile::tempdir().unwrap();
        let boards = dir.path().join("boards");
        std::fs::create_dir(&boards).unwrap();
        for name in ["c.PNG", "a.jpg", "b.tiff", "notes.txt", "d.pgm", "noext", "e.jpeg.bak"] {
            std::fs::write(boards.join(name), b"x").unwrap();
        }
        let single = dir.path().join("z.png");
        let got = expand_image_paths(&[single.clone(), boards.clone(), PathBuf::from("missing.jpg")]).unwrap();
        let want: Vec<PathBuf> = vec![
            single,
            boards.join("a.jpg"),
            boards.join("b.tiff"),
            boards.join("c.PNG"),
            boards.join("d.pgm"),
            PathBuf::from("missing.jpg"),
        ];
        assert_eq!(got, want);
    }

    #[test]
    fn a_directory_without_images_is_an_error_naming_it() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("readme.txt"), b"x").unwrap();
        let err = expand_image_paths(&[dir.path().to_path_buf()]).unwrap_err();
        assert_eq!(err.to_string(), format!("{}: no images in directory", dir.path().display()));
        assert_eq!(expand_image_paths(&[]).unwrap(), Vec::<PathBuf>::new());
    }

    fn ramp(bit_depth: u8) -> GrayImage {
        let mut img = GrayImage::new(7, 5, bit_depth);
        for (i, v) in img.data.iter_mut().enumerate() {
            *v = if bit_depth == 8 { (i * 7) as u16 } else { (i * 1800) as u16 };
        }
        img
    }

    #[test]
    fn png_8_and_16_bit_round_trip_exactly() {
        let dir = tempfile::tempdir().unwrap();
        for depth in [8, 16] {
            let img = ramp(depth);
            let p = dir.path().join(format!("r{depth}.png"));
            write_gray_png(&p, &img).unwrap();
            assert_eq!(load_gray(&p).unwrap(), img);
        }
    }

    /// PGM written byte by byte from netpbm's `pgm(5)`: `P5`, width, height and maxval as text,
    /// one whitespace byte, then the samples (big-endian pairs when maxval > 255).
    #[test]
    fn binary_pgm_8_and_16_bit_load_exactly() {
        let mut p8 = b"P5\n3 2\n255\n".to_vec();
        p8.extend([0u8, 7, 255, 1, 2, 3]);
        let g = decode_gray(&p8, "f.pgm").unwrap();
        assert_eq!((g.width, g.height, g.bit_depth), (3, 2, 8));
        assert_eq!(g.data, vec![0, 7, 255, 1, 2, 3]);
        let samples = [0u16, 258, 65535, 40000];
        let mut p16 = b"P5 2 2 65535\n".to_vec();
        p16.extend(samples.iter().flat_map(|v| v.to_be_bytes()));
        let g = decode_gray(&p16, "f16.pgm").unwrap();
        assert_eq!((g.width, g.height, g.bit_depth), (2, 2, 16));
        assert_eq!(g.data, samples.to_vec());
        let e = decode_gray(&p16[..p16.len() - 3], "cut.pgm").unwrap_err().to_string();
        assert!(e.starts_with("cut.pgm: ") && e.contains("truncated"), "{e}");
        let e = decode_gray(b"P5\n100000 8\n255\n", "huge.pgm").unwrap_err().to_string();
        assert!(e.contains("100000x8"), "{e}");
    }

    /// The plain 8-bit PGM read without the decoder gives what the decoder gives; headers it does
    /// not take (a comment, maxval 1000, a sample too many or too few) go to the decoder.
    #[test]
    fn plain_8_bit_pgm_is_read_as_the_decoder_reads_it() {
        let dir = tempfile::tempdir().unwrap();
        let samples: Vec<u8> = (0..70u32 * 3).map(|i| (i * 37 % 256) as u8).collect();
        let eight = |d: DecodedGray| match d {
            DecodedGray::Eight { width, height, data } => (width, height, data),
            DecodedGray::Wide(_) => panic!("a wide frame"),
        };
        for header in ["P5\n70 3\n255\n", "P5 70 3 255 ", "P5\n70\t3\r\n255\n", "P5\n# a comment\n70 3\n255\n"] {
            let path = dir.path().join("f.pgm");
            let mut bytes = header.as_bytes().to_vec();
            bytes.extend(&samples);
            std::fs::write(&path, &bytes).unwrap();
            let direct = matches!(read_frame_file(&path), Ok(FrameFile::PlainPgm8(_)));
            assert_eq!(direct, !header.contains('#'), "{header:?}");
            let decoded = decode_gray(&bytes, "f.pgm").unwrap();
            assert_eq!((decoded.width, decoded.height), (70, 3));
            assert_eq!(eight(load_gray_decoded(&path).unwrap()), (70, 3, samples.clone()), "{header:?}");
        }
        let path = dir.path().join("g.pgm");
        for (header, extra) in [("P5\n70 3\n255\n", 1), ("P5\n70 3\n255\n", -1), ("P5\n70 3\n1000\n", 0)] {
            let mut bytes = header.as_bytes().to_vec();
            bytes.extend(&samples[..(samples.len() as i64 + extra.min(0)) as usize]);
            bytes.extend(std::iter::repeat_n(9u8, extra.max(0) as usize));
            std::fs::write(&path, &bytes).unwrap();
            assert!(matches!(read_frame_file(&path), Ok(FrameFile::Encoded(b)) if b == bytes), "{header:?} {extra}");
        }
        // The last: 16-bit samples, too few of them: the decoder names the file and the fault.
        let e = load_gray_decoded(&path).err().map(|e| e.to_string()).unwrap_or_default();
        assert!(e.contains("g.pgm") && e.contains("truncated"), "{e}");
    }

    #[test]
    fn jpeg_and_colour_load_as_grey() {
        let dir = tempfile::tempdir().unwrap();
        let rgb: Vec<u8> = (0..16 * 8).flat_map(|_| [100u8, 100, 100]).collect();
        let p = dir.path().join("c.png");
        write_rgb_png(&p, 16, 8, &rgb).unwrap();
        let g = load_gray(&p).unwrap();
        assert_eq!((g.width, g.height, g.bit_depth), (16, 8, 8));
        assert!(g.data.iter().all(|&v| v == 100));
        let jp = dir.path().join("c.jpg");
        image::save_buffer(&jp, &rgb, 16, 8, image::ExtendedColorType::Rgb8).unwrap();
        let g = load_gray(&jp).unwrap();
        assert!(g.data.iter().all(|&v| (v as i32 - 100).abs() <= 2), "{:?}", g.data);
    }

    #[test]
    fn two_channels_of_one_decode_are_the_two_channels_read_apart() {
        use crate::colour::{Channel, Colour};
        let dir = tempfile::tempdir().unwrap();
        let rgb: Vec<u8> = (0..16 * 8u32).flat_map(|k| [(k * 2) as u8, (k % 7 * 9) as u8, (255 - k) as u8]).collect();
        let p = dir.path().join("c.png");
        write_rgb_png(&p, 16, 8, &rgb).unwrap();
        let laser = ColourSpec { channel: Channel::Laser(Colour::Red), bayer: None, sites: false };
        for (spec, also) in [
            (laser, Some(Channel::Single(Colour::Red))),
            (ColourSpec::default(), Some(Channel::Single(Colour::Blue))),
            (laser, None),
        ] {
            let (first, second) = load_frame_channels(&p, &spec, also).unwrap();
            assert_eq!(first.data, load_frame_channel(&p, &spec).unwrap().data);
            let apart = also.map(|c| load_frame_channel(&p, &ColourSpec { channel: c, ..spec }).unwrap().data);
            assert_eq!(second.map(|g| g.data), apart);
        }
    }

    #[test]
    fn bad_files_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let missing = dir.path().join("missing.png");
        let e = load_gray(&missing).unwrap_err().to_string();
        assert!(e.contains("missing.png"), "{e}");
        let text = dir.path().join("text.png");
        std::fs::write(&text, "hello").unwrap();
        let e = load_gray(&text).unwrap_err().to_string();
        assert!(e.contains("text.png") && e.contains("not a PNG"), "{e}");
        let good = dir.path().join("g.png");
        write_gray_png(&good, &ramp(8)).unwrap();
        let bytes = std::fs::read(&good).unwrap();
        let cut = dir.path().join("cut.png");
        std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
        let e = load_gray(&cut).unwrap_err().to_string();
        assert!(e.contains("cut.png") && e.contains("truncated"), "{e}");
        let jpeg = dir.path().join("g.jpg");
        let rgb: Vec<u8> = (0..64 * 32).flat_map(|i| [(i % 251) as u8; 3]).collect();
        image::save_buffer(&jpeg, &rgb, 64, 32, image::ExtendedColorType::Rgb8).unwrap();
        let bytes = std::fs::read(&jpeg).unwrap();
        let mut padded = bytes.clone();
        padded.extend([0u8; 16]);
        assert!(decode_gray(&padded, "padded.jpg").is_ok(), "zero padding after EOI is fine");
        for cut_at in [bytes.len() - 2, bytes.len() - 1, bytes.len() * 3 / 4] {
            let e = decode_gray(&bytes[..cut_at], "cut.jpg").unwrap_err().to_string();
            assert!(e.starts_with("cut.jpg: ") && e.contains("truncated JPEG"), "{e}");
        }
        let header = png_header(100_000, 8);
        let e = decode_gray(&header, "huge.png").unwrap_err().to_string();
        assert!(e.starts_with("huge.png: ") && e.contains("100000x8") && e.contains("16384"), "{e}");
        let empty = dir.path().join("empty.png");
        std::fs::write(&empty, "").unwrap();
        assert!(load_gray(&empty).unwrap_err().to_string().contains("empty.png"));
        for (w, h) in [(0, 0), (0, 4), (4, 0)] {
            let pgm = dir.path().join("none.pgm");
            std::fs::write(&pgm, format!("P5\n{w} {h}\n255\n")).unwrap();
            let e = load_gray_decoded(&pgm).unwrap_err().to_string();
            assert!(e.contains("none.pgm") && e.contains(&format!("image size {w}x{h}: no pixels")), "{e}");
        }
    }

    /// A grey 8-bit PNG claiming the given size, with almost no pixel data.
    fn png_header(width: u32, height: u32) -> Vec<u8> {
        let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
        let mut chunk = |kind: &[u8], data: &[u8]| {
            let mut body = kind.to_vec();
            body.extend(data);
            out.extend((data.len() as u32).to_be_bytes());
            out.extend(&body);
            out.extend(crc32(&body).to_be_bytes());
        };
        let mut ihdr = width.to_be_bytes().to_vec();
        ihdr.extend(height.to_be_bytes());
        ihdr.extend([8, 0, 0, 0, 0]);
        chunk(b"IHDR", &ihdr);
        chunk(b"IDAT", &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01]);
        chunk(b"IEND", &[]);
        out
    }

    fn crc32(data: &[u8]) -> u32 {
        let mut c = 0xFFFF_FFFFu32;
        for &b in data {
            c ^= b as u32;
            for _ in 0..8 {
                c = if c & 1 != 0 { 0xEDB8_8320 ^ (c >> 1) } else { c >> 1 };
            }
        }
        !c
    }

    #[test]
    fn subtraction_clamps_and_checks_size() {
        let mut a = ramp(8);
        let b = GrayImage { data: vec![10; a.data.len()], ..a.clone() };
        a.subtract_saturating(&b).unwrap();
        assert_eq!(a.data[0], 0);
        assert_eq!(a.data[3], 11);
        let small = GrayImage::new(3, 3, 8);
        assert!(a.subtract_saturating(&small).unwrap_err().contains("3x3"));
    }
}
