//! The chosen UAV's camera frames as images: labels and depth as PNG
//! `foxglove.CompressedImage`s, the identified targets' boxes as `foxglove.ImageAnnotations`.
//!
//! PNG keeps the label image exact and small (a few large areas of four colours). The depth
//! image holds the measured range in whole metres as 8-bit grey, 0 where nothing was measured
//! and 255 from 255 m on: the ranges' noise (a percent of the range) makes finer steps
//! incompressible, about 280 kB an image in centimetres against tens of kB in metres. The
//! frames themselves, exact, are `fleet render`'s.

use foxglove::messages::{
    Color, CompressedImage, ImageAnnotations, Point2, PointsAnnotation, TextAnnotation, Timestamp,
    points_annotation,
};
use protocol::frame::CvsFrame;

use super::topics::camera_frame;
use crate::pictures::frame::label_colour;

/// Why an image could not be made.
#[derive(Debug, thiserror::Error)]
#[error("cannot encode the camera image as PNG: {0}")]
pub struct ImageError(#[from] png::EncodingError);

/// The frame's labels, a colour per class as `fleet render` draws them.
pub fn labels(frame: &CvsFrame, stamp: Timestamp) -> Result<CompressedImage, ImageError> {
    let (rows, cols) = (frame.header.rows, frame.header.cols);
    let mut rgb = Vec::with_capacity(rows as usize * cols as usize * 3);
    for r in 0..rows {
        for c in 0..cols {
            let colour = label_colour(frame.label(r, c));
            rgb.extend_from_slice(&[colour.0, colour.1, colour.2]);
        }
    }
    let data = encode(cols, rows, png::ColorType::Rgb, png::BitDepth::Eight, &rgb)?;
    Ok(image(frame, data, stamp))
}

/// The frame's measured ranges in whole metres, 8-bit grey (0: not measured; 255: 255 m or
/// more; a range under a metre reads 1).
pub fn depth(frame: &CvsFrame, stamp: Timestamp) -> Result<CompressedImage, ImageError> {
    let (rows, cols) = (frame.header.rows, frame.header.cols);
    let mut grey = Vec::with_capacity(rows as usize * cols as usize);
    for r in 0..rows {
        for c in 0..cols {
            grey.push(metres(frame.depth_at(r, c)));
        }
    }
    let data = encode(
        cols,
        rows,
        png::ColorType::Grayscale,
        png::BitDepth::Eight,
        &grey,
    )?;
    Ok(image(frame, data, stamp))
}

/// A range as whole metres, at least 1; 0 for no measurement.
fn metres(range_m: f32) -> u8 {
    if range_m.is_finite() && range_m > 0.0 {
        range_m.round().clamp(1.0, 255.0) as u8
    } else {
        0
    }
}

/// The boxes of the targets the frame identifies, with their ids.
pub fn boxes(frame: &CvsFrame, stamp: Timestamp) -> ImageAnnotations {
    const INK: Color = Color {
        r: 1.0,
        g: 0.9,
        b: 0.0,
        a: 1.0,
    };
    let valid = frame
        .boxes()
        .iter()
        .filter(|b| b.is_valid(frame.header.rows, frame.header.cols));
    let points = valid
        .clone()
        .map(|b| {
            let (x0, y0, x1, y1) = (
                f64::from(b.c0),
                f64::from(b.r0),
                f64::from(b.c1),
                f64::from(b.r1),
            );
            PointsAnnotation {
                timestamp: Some(stamp),
                r#type: points_annotation::Type::LineLoop as i32,
                points: vec![
                    Point2 { x: x0, y: y0 },
                    Point2 { x: x1, y: y0 },
                    Point2 { x: x1, y: y1 },
                    Point2 { x: x0, y: y1 },
                ],
                outline_color: Some(INK),
                thickness: 2.0,
                ..Default::default()
            }
        })
        .collect();
    let texts = valid
        .map(|b| TextAnnotation {
            timestamp: Some(stamp),
            position: Some(Point2 {
                x: f64::from(b.c0),
                y: f64::from(b.r0.saturating_sub(2)),
            }),
            text: format!("{}", b.id),
            font_size: 14.0,
            text_color: Some(INK),
            background_color: Some(Color {
                r: 0.0,
                g: 0.0,
                b: 0.0,
                a: 0.6,
            }),
            metadata: Vec::new(),
        })
        .collect();
    ImageAnnotations {
        timestamp: Some(stamp),
        circles: Vec::new(),
        points,
        texts,
        metadata: Vec::new(),
    }
}

fn image(frame: &CvsFrame, data: Vec<u8>, stamp: Timestamp) -> CompressedImage {
    CompressedImage {
        timestamp: Some(stamp),
        frame_id: camera_frame(frame.header.uav),
        data: data.into(),
        format: "png".into(),
    }
}

fn encode(
    width: u32,
    height: u32,
    colour: png::ColorType,
    depth: png::BitDepth,
    pixels: &[u8],
) -> Result<Vec<u8>, ImageError> {
    let mut out = Vec::new();
    let mut encoder = png::Encoder::new(&mut out, width, height);
    encoder.set_color(colour);
    encoder.set_depth(depth);
    encoder.set_compression(png::Compression::Fast);
    let mut writer = encoder.write_header()?;
    writer.write_image_data(pixels)?;
    writer.finish()?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use protocol::frame::TargetBox;

    fn frame() -> Box<CvsFrame> {
        let mut f = CvsFrame::new_boxed();
        f.header.uav = 3;
        f.header.rows = 4;
        f.header.cols = 6;
        f
    }

    fn decode(image: &CompressedImage) -> (png::OutputInfo, Vec<u8>) {
        let decoder = png::Decoder::new(std::io::Cursor::new(image.data.to_vec()));
        let mut reader = decoder.read_info().expect("a PNG");
        let mut buf = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut buf).expect("a frame");
        buf.truncate(info.buffer_size());
        (info, buf)
    }

    #[test]
    fn depth_reads_back_in_metres() {
        let mut f = frame();
        f.depth[0] = 12.6;
        f.depth[1] = f32::NAN;
        f.depth[2] = 1e6;
        f.depth[3] = 0.2;
        let image = depth(&f, Timestamp::new(1, 0)).expect("encoded");
        assert_eq!(image.frame_id, "uav3/camera");
        let (info, data) = decode(&image);
        assert_eq!((info.width, info.height), (6, 4));
        assert_eq!(info.bit_depth, png::BitDepth::Eight);
        assert_eq!(&data[..5], &[13, 0, 255, 1, 0]);
    }

    #[test]
    fn labels_take_the_class_colours_and_boxes_their_ids() {
        let mut f = frame();
        f.labels[7] = 1;
        f.header.box_count = 2;
        f.boxes[0] = TargetBox {
            id: 9,
            r0: 1,
            c0: 1,
            r1: 3,
            c1: 2,
        };
        // Outside the image: not drawn.
        f.boxes[1] = TargetBox {
            id: 4,
            r0: 1,
            c0: 1,
            r1: 9,
            c1: 2,
        };
        let (_, rgb) = decode(&labels(&f, Timestamp::new(0, 0)).expect("encoded"));
        let target = label_colour(protocol::frame::Label::Target);
        assert_eq!(&rgb[21..24], &[target.0, target.1, target.2]);
        let annotations = boxes(&f, Timestamp::new(0, 0));
        assert_eq!(annotations.points.len(), 1);
        assert_eq!(annotations.texts[0].text, "9");
    }
}
