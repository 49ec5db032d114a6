//! OpenEXR files read and written in pure Rust (the `exr` crate): Blender's multilayer renders,
//! the recomposited frames and environment maps. No C library of its own is linked, so nothing
//! here can collide with the OpenEXR library that a Blender build loads into its own process
//! (two copies of OpenEXR's C symbols in one process make the second reader call the first's
//! functions, which crashes).
//!
//! [`read`] returns every part of a flat (not deep) file, scanline or tiled (the full-resolution
//! level), in the compressions the crate decodes exactly as OpenEXR does: NONE, RLE, ZIPS, ZIP
//! (Blender's default), PIZ, PXR24, B44 and B44A. Pixels cover the data window, row 0 at its top
//! (`y = ymin`); half channels are widened to f32 exactly, uint channels stay u32. DWAA/DWAB (the
//! crate's decoding of these lossy codecs differs from OpenEXR's in a few pixels) are refused
//! unless asked for (`dwa`); subsampled channels and deep data are refused with an error naming
//! them. [`write`] writes one scanline
//! part of float or half channels with string attributes.
//!
//! Every failure is a [`RokebyError`]: a malformed, truncated or unsupported file is
//! `InvalidArgument` naming what is wrong, a size over the memory limit is `OutOfMemory` (checked
//! from the header before any pixel is allocated).

use crate::error::{Result, RokebyError};
use exr::prelude::*;
use std::io::Cursor;

fn bad(msg: impl Into<String>) -> RokebyError {
    RokebyError::invalid("data", msg)
}

/// Which sample type a channel has in the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SampleType {
    Half,
    Float,
    Uint,
}

impl SampleType {
    /// The name OpenEXR gives the type ("half", "float", "uint").
    pub fn name(self) -> &'static str {
        match self {
            SampleType::Half => "half",
            SampleType::Float => "float",
            SampleType::Uint => "uint",
        }
    }
}

/// A channel's pixels, row-major over the data window (`height × width`).
#[derive(Debug, Clone, PartialEq)]
pub enum Samples {
    /// Half (widened exactly) or float samples.
    F32(Vec<f32>),
    /// Unsigned integer samples.
    U32(Vec<u32>),
}

#[derive(Debug, Clone, PartialEq)]
pub struct Channel {
    pub name: String,
    pub sample_type: SampleType,
    pub samples: Samples,
}

/// A header attribute whose value is a string, an integer or a float (the others — vectors,
/// matrices, chromaticities, previews, … — are not returned).
#[derive(Debug, Clone, PartialEq)]
pub enum AttrValue {
    Text(String),
    Int(i64),
    Float(f64),
}

/// One part of a file.
#[derive(Debug, Clone, PartialEq)]
pub struct Part {
    /// The part's `name` attribute (multi-part files), if any.
    pub name: Option<String>,
    pub width: usize,
    pub height: usize,
    /// `(xmin, ymin, xmax, ymax)`, inclusive, as in the file.
    pub data_window: [i32; 4],
    pub display_window: [i32; 4],
    /// OpenEXR's name of the compression ("none", "rle", "zips", "zip", "piz", "pxr24", "b44",
    /// "b44a", "dwaa", "dwab").
    pub compression: &'static str,
    pub tiled: bool,
    /// String, integer and float attributes by their names in the file, sorted by name.
    pub attributes: Vec<(String, AttrValue)>,
    /// The channels in the file's (alphabetical) order.
    pub channels: Vec<Channel>,
}

/// OpenEXR's name of a compression method.
pub fn compression_name(c: Compression) -> &'static str {
    match c {
        Compression::Uncompressed => "none",
        Compression::RLE => "rle",
        Compression::ZIP1 => "zips",
        Compression::ZIP16 => "zip",
        Compression::PIZ => "piz",
        Compression::PXR24 => "pxr24",
        Compression::B44 => "b44",
        Compression::B44A => "b44a",
        Compression::DWAA(_) => "dwaa",
        Compression::DWAB(_) => "dwab",
        _ => "unknown",
    }
}

fn text(t: &Text) -> String {
    // OpenEXR strings are bytes; Blender writes UTF-8 (scene and camera names).
    String::from_utf8_lossy(t.as_slice()).into_owned()
}

fn bounds(b: IntegerBounds) -> [i32; 4] {
    let max = b.max();
    [b.position.x(), b.position.y(), max.x(), max.y()]
}

fn file_error(e: exr::error::Error) -> RokebyError {
    use exr::error::Error as E;
    match e {
        E::NotSupported(msg) => bad(format!("unsupported EXR feature: {msg}")),
        E::Invalid(msg) => bad(format!(
            "not a readable EXR (truncated or corrupted?): invalid {msg}"
        )),
        E::Io(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            bad("not a readable EXR: the file ends early (truncated?)")
        }
        E::Io(io) => bad(format!("not a readable EXR: {io}")),
        E::Aborted => RokebyError::Cancelled,
    }
}

/// Checks what the headers ask for (pixels of every channel, as f32/u32, of the full-resolution
/// level) against the memory limit before the crate allocates anything, and refuses what the
/// reader does not return (deep data, subsampled channels) with a message naming it.
fn check_headers(bytes: &[u8], dwa: bool) -> Result<exr::meta::MetaData> {
    if bytes.len() < 4 || bytes[..4] != [0x76, 0x2f, 0x31, 0x01] {
        let head: String = String::from_utf8_lossy(&bytes[..bytes.len().min(8)])
            .chars()
            .filter(|c| !c.is_control())
            .collect();
        return Err(bad(format!(
            "not an OpenEXR file (it starts {head:?}, expected the EXR magic number 76 2f 31 01)"
        )));
    }
    let meta =
        exr::meta::MetaData::read_from_buffered(Cursor::new(bytes), false).map_err(file_error)?;
    if meta.headers.is_empty() {
        return Err(bad("not a readable EXR: it has no parts"));
    }
    let mut samples = 0usize;
    for (i, h) in meta.headers.iter().enumerate() {
        if h.deep {
            return Err(bad(format!(
                "part {i} holds deep data, which is not supported (only flat images)"
            )));
        }
        if let (false, Compression::DWAA(_) | Compression::DWAB(_)) = (dwa, h.compression) {
            return Err(bad(format!(
                "{} compression is not supported: the crate's decoder of this lossy codec differs \
                 from OpenEXR's in some pixels (measured up to 0.2%), so the file would not read as \
                 it does in Blender; save it with a lossless codec such as ZIP (Blender's default)",
                compression_name(h.compression).to_uppercase()
            )));
        }
        if let Some(c) = h.channels.list.iter().find(|c| c.sampling != Vec2(1, 1)) {
            return Err(bad(format!(
                "channel {:?} is subsampled ({}×{}), which is not supported",
                text(&c.name),
                c.sampling.x(),
                c.sampling.y()
            )));
        }
        let area = h.layer_size.x().checked_mul(h.layer_size.y());
        let n = area.and_then(|a| a.checked_mul(h.channels.list.len()));
        samples = n
            .and_then(|n| samples.checked_add(n))
            .ok_or_else(|| bad("the data window is too large"))?;
    }
    // The crate's f16 buffers plus the widened f32 copies: 6 bytes per sample at most at once.
    crate::alloc::check::<[u8; 6]>("EXR pixels", &[samples])?;
    Ok(meta)
}

/// Every part of the EXR file `bytes` (see the module documentation). `dwa`: decode DWAA/DWAB
/// files too, accepting that a few pixels differ from OpenEXR's decoding by a rounding (for
/// environment maps: Blender's own studio worlds are DWAB), instead of refusing them.
pub fn read(bytes: &[u8], dwa: bool) -> Result<Vec<Part>> {
    let meta = check_headers(bytes, dwa)?;
    // Multi-part files carry each part's chunk count as an attribute (the crate keeps it apart).
    let chunk_counts: Vec<Option<usize>> = meta
        .headers
        .iter()
        .map(|h| {
            meta.requirements
                .has_multiple_layers
                .then_some(h.chunk_count)
        })
        .collect();
    let image = exr::image::read::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .non_parallel()
        .from_buffered(Cursor::new(bytes))
        .map_err(file_error)?;
    let shared = &image.attributes;
    let display_window = bounds(shared.display_window);
    let mut parts = Vec::with_capacity(image.layer_data.len());
    for (index, layer) in image.layer_data.iter().enumerate() {
        let a = &layer.attributes;
        let (w, h) = (layer.size.x(), layer.size.y());
        let data_window = bounds(IntegerBounds::new(a.layer_position, layer.size));
        let mut attrs: Vec<(String, AttrValue)> = Vec::new();
        let put_text = |k: &str, v: &Option<Text>, attrs: &mut Vec<_>| {
            if let Some(v) = v {
                attrs.push((k.to_string(), AttrValue::Text(text(v))));
            }
        };
        put_text("name", &a.layer_name, &mut attrs);
        put_text(
            "renderingTransform",
            &a.rendering_transform_name,
            &mut attrs,
        );
        put_text(
            "lookModTransform",
            &a.look_modification_transform_name,
            &mut attrs,
        );
        put_text("owner", &a.owner, &mut attrs);
        put_text("comments", &a.comments, &mut attrs);
        put_text("capDate", &a.capture_date, &mut attrs);
        put_text("wrapmodes", &a.wrap_mode_name, &mut attrs);
        put_text("view", &a.view_name, &mut attrs);
        put_text("software", &a.software_name, &mut attrs);
        let floats = [
            ("pixelAspectRatio", Some(shared.pixel_aspect)),
            ("screenWindowWidth", Some(a.screen_window_width)),
            ("whiteLuminance", a.white_luminance),
            ("xDensity", a.horizontal_density),
            ("utcOffset", a.utc_offset),
            ("longitude", a.longitude),
            ("latitude", a.latitude),
            ("altitude", a.altitude),
            ("focus", a.focus),
            ("expTime", a.exposure),
            ("aperture", a.aperture),
            ("isoSpeed", a.iso_speed),
            ("nearClip", a.near_clip_plane),
            ("farClip", a.far_clip_plane),
            ("fieldOfViewHorizontal", a.horizontal_field_of_view),
            ("fieldOfViewVertical", a.vertical_field_of_view),
        ];
        for (k, v) in floats {
            if let Some(v) = v {
                attrs.push((k.to_string(), AttrValue::Float(v as f64)));
            }
        }
        for (k, v) in shared.other.iter().chain(a.other.iter()) {
            let v = match v {
                AttributeValue::Text(t) => AttrValue::Text(text(t)),
                AttributeValue::I32(i) => AttrValue::Int(*i as i64),
                AttributeValue::F32(f) => AttrValue::Float(*f as f64),
                AttributeValue::F64(f) => AttrValue::Float(*f),
                _ => continue,
            };
            attrs.push((text(k), v));
        }
        if let Some(Some(n)) = chunk_counts.get(index) {
            attrs.push(("chunkCount".to_string(), AttrValue::Int(*n as i64)));
        }
        attrs.sort_by(|x, y| x.0.cmp(&y.0));
        attrs.dedup_by(|x, y| x.0 == y.0);
        let mut channels = Vec::with_capacity(layer.channel_data.list.len());
        for c in layer.channel_data.list.iter() {
            let (sample_type, samples) = match &c.sample_data {
                FlatSamples::F16(v) => (
                    SampleType::Half,
                    Samples::F32(v.iter().map(|x| x.to_f32()).collect()),
                ),
                FlatSamples::F32(v) => (SampleType::Float, Samples::F32(v.clone())),
                FlatSamples::U32(v) => (SampleType::Uint, Samples::U32(v.clone())),
            };
            let n = match &samples {
                Samples::F32(v) => v.len(),
                Samples::U32(v) => v.len(),
            };
            if n != w * h {
                return Err(RokebyError::Internal(format!(
                    "EXR channel {:?}: {n} samples for a {w}×{h} data window",
                    text(&c.name)
                )));
            }
            channels.push(Channel {
                name: text(&c.name),
                sample_type,
                samples,
            });
        }
        parts.push(Part {
            name: a.layer_name.as_ref().map(text),
            width: w,
            height: h,
            data_window,
            display_window,
            compression: compression_name(layer.encoding.compression),
            tiled: matches!(layer.encoding.blocks, Blocks::Tiles(_)),
            attributes: attrs,
            channels,
        });
    }
    Ok(parts)
}

/// A channel or attribute name as OpenEXR stores it: UTF-8 bytes (as Blender writes them), 1 to
/// 255 of them, no NUL.
fn valid_name(name: &str) -> Option<Text> {
    (!name.is_empty() && name.len() < 256 && !name.contains('\0'))
        .then(|| Text::from_slice_unchecked(name.as_bytes()))
}

/// A channel to write: `height × width` samples, row 0 at the top, stored as half or float.
pub struct WriteChannel<'a> {
    pub name: &'a str,
    pub samples: &'a [f32],
    pub half: bool,
}

/// The compression of a name OpenEXR uses ("none", "rle", "zips", "zip", "piz", "pxr24", "b44",
/// "b44a"), for writing.
pub fn compression_from_name(name: &str) -> Result<Compression> {
    Ok(match name.to_ascii_lowercase().as_str() {
        "none" => Compression::Uncompressed,
        "rle" => Compression::RLE,
        "zips" => Compression::ZIP1,
        "zip" => Compression::ZIP16,
        "piz" => Compression::PIZ,
        "pxr24" => Compression::PXR24,
        "b44" => Compression::B44,
        "b44a" => Compression::B44A,
        _ => {
            return Err(RokebyError::invalid(
                "compression",
                format!("{name:?} is not one of none, rle, zips, zip, piz, pxr24, b44, b44a"),
            ))
        }
    })
}

/// Attribute names the writer sets itself, or that hold non-string values in OpenEXR.
const RESERVED: &[&str] = &[
    "channels",
    "compression",
    "dataWindow",
    "displayWindow",
    "lineOrder",
    "pixelAspectRatio",
    "screenWindowCenter",
    "screenWindowWidth",
    "tiles",
    "type",
    "version",
    "chunkCount",
    "maxSamplesPerPixel",
    "whiteLuminance",
    "adoptedNeutral",
    "xDensity",
    "utcOffset",
    "longitude",
    "latitude",
    "altitude",
    "focus",
    "expTime",
    "aperture",
    "isoSpeed",
    "envmap",
    "keyCode",
    "timeCode",
    "framesPerSecond",
    "multiView",
    "worldToCamera",
    "worldToNDC",
    "deepImageState",
    "originalDataWindow",
    "dwaCompressionLevel",
    "preview",
    "chromaticities",
    "nearClip",
    "farClip",
    "fieldOfViewHorizontal",
    "fieldOfViewVertical",
];

/// The bytes of a one-part scanline EXR of `channels` (`height × width` each; written in
/// alphabetical order, as OpenEXR stores them), with the string `attributes`, data and display
/// windows `(0, 0)–(width−1, height−1)`, increasing-y line order.
pub fn write(
    width: usize,
    height: usize,
    channels: &[WriteChannel<'_>],
    attributes: &[(&str, &str)],
    compression: Compression,
) -> Result<Vec<u8>> {
    if width == 0 || height == 0 || width > i32::MAX as usize / 2 || height > i32::MAX as usize / 2
    {
        return Err(RokebyError::invalid(
            "pixels",
            format!("an EXR needs a size of at least 1×1 (and below 2^30), got {width}×{height}"),
        ));
    }
    if channels.is_empty() {
        return Err(RokebyError::invalid("channels", "no channels to write"));
    }
    let n = width * height;
    let mut seen = std::collections::HashSet::new();
    let mut list = SmallVec::<[AnyChannel<FlatSamples>; 4]>::new();
    for c in channels {
        let name = valid_name(c.name).ok_or_else(|| {
            RokebyError::invalid(
                "channels",
                format!(
                    "{:?} is not a valid EXR channel name (1 to 255 bytes, no NUL)",
                    c.name
                ),
            )
        })?;
        if !seen.insert(c.name) {
            return Err(RokebyError::invalid(
                "channels",
                format!("channel {:?} given twice", c.name),
            ));
        }
        if c.samples.len() != n {
            return Err(RokebyError::invalid(
                "channels",
                format!(
                    "channel {:?} has {} samples, expected {width}×{height} = {n}",
                    c.name,
                    c.samples.len()
                ),
            ));
        }
        let data = if c.half {
            let mut v = crate::alloc::with_capacity::<f16>("EXR channel", &[n])?;
            v.extend(c.samples.iter().map(|&x| f16::from_f32(x)));
            FlatSamples::F16(v)
        } else {
            let mut v = crate::alloc::with_capacity::<f32>("EXR channel", &[n])?;
            v.extend_from_slice(c.samples);
            FlatSamples::F32(v)
        };
        list.push(AnyChannel::new(name, data));
    }
    let mut attrs = LayerAttributes::default();
    for &(k, v) in attributes {
        let key = valid_name(k).ok_or_else(|| {
            RokebyError::invalid(
                "header",
                format!("{k:?} is not a valid EXR attribute name (1 to 255 bytes, no NUL)"),
            )
        })?;
        if RESERVED.contains(&k) {
            return Err(RokebyError::invalid(
                "header",
                format!("attribute {k:?} is set by the writer or is not a string in OpenEXR"),
            ));
        }
        if v.contains('\0') {
            return Err(RokebyError::invalid(
                "header",
                format!("attribute {k:?}: a string with a NUL character"),
            ));
        }
        let value = Some(Text::from_slice_unchecked(v.as_bytes()));
        match k {
            "name" => attrs.layer_name = value,
            "renderingTransform" => attrs.rendering_transform_name = value,
            "lookModTransform" => attrs.look_modification_transform_name = value,
            "owner" => attrs.owner = value,
            "comments" => attrs.comments = value,
            "capDate" => attrs.capture_date = value,
            "wrapmodes" => attrs.wrap_mode_name = value,
            "view" => attrs.view_name = value,
            "software" => attrs.software_name = value,
            _ => {
                attrs.other.insert(
                    key,
                    AttributeValue::Text(Text::from_slice_unchecked(v.as_bytes())),
                );
            }
        }
    }
    let encoding = Encoding {
        compression,
        blocks: Blocks::ScanLines,
        line_order: LineOrder::Increasing,
    };
    let layer = Layer::new(
        Vec2(width, height),
        attrs,
        encoding,
        AnyChannels::sort(list),
    );
    let image = Image::from_layer(layer);
    let mut out = Cursor::new(Vec::new());
    image
        .write()
        .non_parallel()
        .to_buffered(&mut out)
        .map_err(|e| match e {
            exr::error::Error::Io(io) => RokebyError::Internal(format!("writing an EXR: {io}")),
            other => {
                RokebyError::invalid("pixels", format!("cannot be written as an EXR: {other}"))
            }
        })?;
    Ok(out.into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: usize, h: usize, k: f32) -> Vec<f32> {
        (0..w * h).map(|i| (i as f32) * k - 3.5).collect()
    }

    #[test]
    fn float_and_half_channels_round_trip_in_every_lossless_compression() {
        let (w, h) = (37, 21);
        let r = ramp(w, h, 0.25);
        let g = ramp(w, h, -1.0 / 3.0);
        let half_exact: Vec<f32> = r.iter().map(|&x| f16::from_f32(x).to_f32()).collect();
        for comp in ["none", "rle", "zips", "zip", "piz"] {
            let bytes = write(
                w,
                h,
                &[
                    WriteChannel {
                        name: "R",
                        samples: &r,
                        half: false,
                    },
                    WriteChannel {
                        name: "G",
                        samples: &g,
                        half: false,
                    },
                    WriteChannel {
                        name: "Y",
                        samples: &r,
                        half: true,
                    },
                ],
                &[("Note", "ä note"), ("comments", "c")],
                compression_from_name(comp).unwrap(),
            )
            .unwrap();
            let parts = read(&bytes, false).unwrap();
            assert_eq!(parts.len(), 1);
            let p = &parts[0];
            assert_eq!((p.width, p.height), (w, h));
            assert_eq!(p.data_window, [0, 0, w as i32 - 1, h as i32 - 1]);
            assert_eq!(p.display_window, p.data_window);
            assert_eq!(p.compression, comp);
            let names: Vec<_> = p.channels.iter().map(|c| c.name.as_str()).collect();
            assert_eq!(names, ["G", "R", "Y"]);
            assert_eq!(p.channels[0].samples, Samples::F32(g.clone()));
            assert_eq!(p.channels[1].samples, Samples::F32(r.clone()));
            assert_eq!(p.channels[2].sample_type, SampleType::Half);
            assert_eq!(p.channels[2].samples, Samples::F32(half_exact.clone()));
            assert!(p
                .attributes
                .contains(&("Note".into(), AttrValue::Text("ä note".into()))));
            assert!(p
                .attributes
                .contains(&("comments".into(), AttrValue::Text("c".into()))));
            assert!(p
                .attributes
                .contains(&("pixelAspectRatio".into(), AttrValue::Float(1.0))));
        }
    }

    #[test]
    fn bad_files_are_errors_naming_what_is_wrong() {
        let r = ramp(8, 8, 1.0);
        let good = write(
            8,
            8,
            &[WriteChannel {
                name: "R",
                samples: &r,
                half: false,
            }],
            &[],
            Compression::ZIP16,
        )
        .unwrap();
        let e = read(b"#?RADIANCE\nnot an exr", false)
            .unwrap_err()
            .to_string();
        assert!(e.contains("not an OpenEXR file"), "{e}");
        let e = read(&[], false).unwrap_err().to_string();
        assert!(e.contains("not an OpenEXR file"), "{e}");
        for cut in [5, 20, good.len() / 2, good.len() - 3] {
            let e = read(&good[..cut], false).unwrap_err();
            assert!(
                matches!(e, RokebyError::InvalidArgument { .. }),
                "{cut}: {e}"
            );
        }
        let dwa = write(
            8,
            8,
            &[WriteChannel {
                name: "R",
                samples: &r,
                half: false,
            }],
            &[],
            Compression::DWAA(None),
        )
        .unwrap();
        let e = read(&dwa, false).unwrap_err().to_string();
        assert!(
            e.contains("DWAA compression is not supported") && e.contains("ZIP"),
            "{e}"
        );
        let p = read(&dwa, true).unwrap();
        assert_eq!(p[0].compression, "dwaa");
        // Every single-byte change either reads or is an error; none panics.
        for i in 0..good.len() {
            let mut b = good.clone();
            b[i] ^= 0xA5;
            let _ = std::panic::catch_unwind(|| read(&b, true)).expect("no panic");
        }
    }

    #[test]
    fn bad_write_arguments_are_refused() {
        let r = ramp(4, 4, 1.0);
        let one = |name, n: usize| {
            write(
                4,
                4,
                &[WriteChannel {
                    name,
                    samples: &r[..n],
                    half: false,
                }],
                &[],
                Compression::ZIP16,
            )
        };
        assert!(one("R", 15)
            .unwrap_err()
            .to_string()
            .contains("expected 4×4"));
        assert!(one("", 16)
            .unwrap_err()
            .to_string()
            .contains("channel name"));
        let e = write(
            4,
            4,
            &[WriteChannel {
                name: "R",
                samples: &r,
                half: false,
            }],
            &[("dataWindow", "x")],
            Compression::ZIP16,
        )
        .unwrap_err();
        assert!(e.to_string().contains("dataWindow"), "{e}");
        assert!(compression_from_name("dwaa").is_err());
    }
}
