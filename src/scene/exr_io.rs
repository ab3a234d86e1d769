//! EXR reading of selected channels only, and atomic EXR writing.

use std::collections::HashMap;
use std::fs::File;
use std::io::BufReader;
use std::path::Path;

use exr::block::chunk::Chunk;
use exr::block::reader::ChunksReader;
use exr::meta::attribute::SampleType;

use super::SceneError;

/// Names of every channel of the first layer of an EXR file, and its size.
pub fn channel_names(path: &Path) -> Result<(Vec<String>, usize, usize), SceneError> {
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| SceneError::exr(path, e))?;
    let header = meta
        .headers
        .first()
        .ok_or_else(|| SceneError::Exr { file: path.to_path_buf(), message: "the file has no image layer".into() })?;
    let names = header.channels.list.iter().map(|c| c.name.to_string()).collect();
    Ok((names, header.layer_size.width(), header.layer_size.height()))
}

/// The text attributes of the first layer's header (the image's and the
/// layer's own), by name: what a renderer wrote about the render.
pub fn text_attributes(path: &Path) -> Result<HashMap<String, String>, SceneError> {
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| SceneError::exr(path, e))?;
    let header = meta
        .headers
        .first()
        .ok_or_else(|| SceneError::Exr { file: path.to_path_buf(), message: "the file has no image layer".into() })?;
    let attributes = header.shared_attributes.other.iter().chain(&header.own_attributes.other);
    Ok(attributes
        .filter_map(|(name, value)| match value {
            exr::meta::attribute::AttributeValue::Text(text) => Some((name.to_string(), text.to_string())),
            _ => None,
        })
        .collect())
}

/// Decode the named channels (all must exist) of the first layer; other
/// channels are decompressed with their blocks but never converted or kept.
pub fn read_channels(path: &Path, names: &[&str]) -> Result<ImageChannels, SceneError> {
    let file = File::open(path).map_err(|e| SceneError::io(path, e))?;
    let reader = exr::block::read(BufReader::new(file), false).map_err(|e| SceneError::exr(path, e))?;
    let header = reader
        .headers()
        .first()
        .cloned()
        .ok_or_else(|| SceneError::Exr { file: path.to_path_buf(), message: "the file has no image layer".into() })?;
    let (width, height) = (header.layer_size.width(), header.layer_size.height());
    let list = &header.channels.list;
    let mut wanted: HashMap<usize, usize> = HashMap::new();
    for (slot, name) in names.iter().enumerate() {
        let index =
            list.iter().position(|c| c.name.to_string() == *name).ok_or_else(|| SceneError::MissingChannel {
                file: path.to_path_buf(),
                channel: (*name).to_string(),
                available: list.iter().map(|c| c.name.to_string()).collect(),
            })?;
        wanted.insert(index, slot);
    }
    let mut data = vec![vec![0f32; width * height]; names.len()];
    let chunks = reader.all_chunks(false).map_err(|e| SceneError::exr(path, e))?;
    let meta = chunks.meta_data().clone();
    for chunk in chunks {
        let chunk: Chunk = chunk.map_err(|e| SceneError::exr(path, e))?;
        if chunk.layer_index != 0 {
            continue;
        }
        let block = exr::block::UncompressedBlock::decompress_chunk(chunk, &meta, false)
            .map_err(|e| SceneError::exr(path, e))?;
        for line in block.lines(&header.channels) {
            let Some(&slot) = wanted.get(&line.location.channel) else { continue };
            let (x0, y) = (line.location.position.x(), line.location.position.y());
            if y >= height || x0 + line.location.sample_count > width {
                return Err(SceneError::Exr {
                    file: path.to_path_buf(),
                    message: "a block lies outside the image".into(),
                });
            }
            let row = &mut data[slot][y * width + x0..y * width + x0 + line.location.sample_count];
            let result = match list[line.location.channel].sample_type {
                SampleType::F32 => line.read_samples_into_slice(row),
                SampleType::F16 => {
                    let mut half = vec![exr::prelude::f16::ZERO; row.len()];
                    line.read_samples_into_slice(&mut half).map(|()| {
                        for (dst, src) in row.iter_mut().zip(half) {
                            *dst = src.to_f32();
                        }
                    })
                }
                SampleType::U32 => {
                    let mut ints = vec![0u32; row.len()];
                    line.read_samples_into_slice(&mut ints).map(|()| {
                        for (dst, src) in row.iter_mut().zip(ints) {
                            *dst = src as f32;
                        }
                    })
                }
            };
            result.map_err(|e| SceneError::exr(path, e))?;
        }
    }
    Ok(ImageChannels { width, height, data })
}

/// Channels read from one file, in the order they were asked for.
pub struct ImageChannels {
    pub width: usize,
    pub height: usize,
    pub data: Vec<Vec<f32>>,
}

/// How filterjit writes EXRs: exr's fast lossless encoding, its blocks in
/// increasing order. Its default order is the order parallel compression
/// finishes them in, so the same image gave files of different bytes.
const ORDERED: exr::image::Encoding = exr::image::Encoding {
    line_order: exr::meta::attribute::LineOrder::Increasing,
    ..exr::image::Encoding::FAST_LOSSLESS
};

/// Write an RGB float EXR atomically (temporary file, then rename).
pub fn write_rgb(path: &Path, width: usize, height: usize, rgb: &[[f32; 3]]) -> Result<(), SceneError> {
    use exr::prelude::*;
    let channels = SpecificChannels::rgb(|pos: Vec2<usize>| {
        let [r, g, b] = rgb[pos.y() * width + pos.x()];
        (r, g, b)
    });
    let image = Image::from_encoded_channels((width, height), ORDERED, channels);
    crate::io::write_atomically(path, |tmp| image.write().to_file(tmp).map_err(|e| e.to_string()))
        .map_err(SceneError::from)
}

/// Write named f32 channels as one EXR layer, atomically. Each channel holds width*height values.
pub fn write_channels(
    path: &Path,
    width: usize,
    height: usize,
    channels: &[(&str, Vec<f32>)],
) -> Result<(), SceneError> {
    use exr::prelude::*;
    let list: SmallVec<[AnyChannel<FlatSamples>; 4]> =
        channels.iter().map(|(name, data)| AnyChannel::new(*name, FlatSamples::F32(data.clone()))).collect();
    let layer = Layer::new((width, height), LayerAttributes::default(), ORDERED, AnyChannels::sort(list));
    let image = Image::from_layer(layer);
    crate::io::write_atomically(path, |tmp| image.write().to_file(tmp).map_err(|e| e.to_string()))
        .map_err(SceneError::from)
}
