//! Tone-mapped PNG previews of linear HDR images.

use std::path::Path;

/// Linear → sRGB transfer, after clamping to [0, 1]. Every preview uses this
/// one mapping, so previews of different methods compare directly.
pub fn tone_map(linear: f32) -> u8 {
    let c = if linear.is_finite() { linear.clamp(0.0, 1.0) } else { 0.0 };
    let s = if c <= 0.003_130_8 { 12.92 * c } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 };
    (s * 255.0 + 0.5) as u8
}

/// Write an 8-bit sRGB PNG atomically.
pub fn write_png(path: &Path, width: usize, height: usize, rgb: &[[f32; 3]]) -> Result<(), crate::io::WriteError> {
    let pixels: Vec<u8> = rgb.iter().flat_map(|c| c.map(tone_map)).collect();
    let mut bytes = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut bytes, width as u32, height as u32);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let encode =
            |e: png::EncodingError| crate::io::WriteError::Encode { path: path.to_path_buf(), message: e.to_string() };
        let mut writer = encoder.write_header().map_err(encode)?;
        writer.write_image_data(&pixels).map_err(encode)?;
    }
    crate::io::write_bytes_atomically(path, &bytes)
}

/// Write `frames` (each `width`×`height` linear RGB, tone-mapped as
/// [`write_png`]) as one animated PNG that loops, `fps` frames a second,
/// atomically: a sequence's preview, which browsers play.
pub fn write_animated_png(
    path: &Path,
    width: usize,
    height: usize,
    frames: &[Vec<[f32; 3]>],
    fps: u16,
) -> Result<(), crate::io::WriteError> {
    let encode =
        |e: png::EncodingError| crate::io::WriteError::Encode { path: path.to_path_buf(), message: e.to_string() };
    let mut bytes = Vec::new();
    {
        let mut encoder = png::Encoder::new(&mut bytes, width as u32, height as u32);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_animated(frames.len().max(1) as u32, 0).map_err(encode)?;
        encoder.set_frame_delay(1, fps.max(1)).map_err(encode)?;
        let mut writer = encoder.write_header().map_err(encode)?;
        for frame in frames {
            let pixels: Vec<u8> = frame.iter().flat_map(|c| c.map(tone_map)).collect();
            writer.write_image_data(&pixels).map_err(encode)?;
        }
        writer.finish().map_err(encode)?;
    }
    crate::io::write_bytes_atomically(path, &bytes)
}
