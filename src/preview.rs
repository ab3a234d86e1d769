//! Tone-mapped PNG previews of linear HDR images.

use std::path::Path;

/// An animated preview's longest side and its most frames: a sequence's
/// preview stays a few megabytes whatever the frames' size and number.
pub const ANIMATION_SIDE: usize = 512;
pub const ANIMATION_FRAMES: usize = 240;

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

/// Images of one size side by side, left to right.
pub fn side_by_side(images: &[&[[f32; 3]]], width: usize, height: usize) -> Vec<[f32; 3]> {
    (0..height)
        .flat_map(|y| images.iter().flat_map(move |image| image[y * width..(y + 1) * width].iter().copied()))
        .collect()
}

/// A preview's size: the frame's, or smaller so that its longest side is `longest_side`.
pub fn preview_size(width: usize, height: usize, longest_side: usize) -> (usize, usize) {
    let longest = width.max(height);
    if longest <= longest_side {
        return (width, height);
    }
    ((width * longest_side / longest).max(1), (height * longest_side / longest).max(1))
}

/// `image` (`width`×`height`) at `to_width`×`to_height`, nearest pixel.
pub fn shrunk(image: &[[f32; 3]], width: usize, height: usize, to_width: usize, to_height: usize) -> Vec<[f32; 3]> {
    if (width, height) == (to_width, to_height) {
        return image.to_vec();
    }
    (0..to_height)
        .flat_map(|y| (0..to_width).map(move |x| image[(y * height / to_height) * width + x * width / to_width]))
        .collect()
}
