//! `fishtrack track --overlays`: one picture per frame pair,
//! `OUT/overlays/NNNNNN.png` (paper Fig. 11 style).
//!
//! Each picture is the **rectified** left view and the rectified right view
//! side by side (the views the pipeline works in, so stereo partners lie on
//! the same row), with a white header line naming the frame. On them:
//! - every segmented left object as its oriented box (PCA, Section III),
//!   coloured by track id; objects that no counted track took are thin grey;
//! - the paired right object (Section IV.A) as its upright box in the same
//!   colour, joined to the left box's centre by a line;
//! - a label `id 7 412 mm` above the left box: the track id and the track's
//!   length (median over its measured frames, as in `fish.csv`), or just the
//!   id when the track has no length;
//! - frames a track bridges by prediction (no observation) as a thin upright
//!   box with the label `id 7 ?`.
//!
//! Labels use DejaVu Sans Mono (Bitstream Vera licence, bundled in
//! `host/assets/`). Pictures are written atomically (temp file + rename).

use std::collections::{BTreeMap, BTreeSet};

use ab_glyph::{FontRef, PxScale};
use image::{GrayImage, Rgb, RgbImage};
use imageproc::drawing::{draw_line_segment_mut, draw_text_mut, text_size};

use fishtrack_core::image::Roi;
use fishtrack_core::object::OrientedBox;
use fishtrack_core::pipeline::PipelineEvent;

use crate::error::InputError;
use crate::output::FishOut;
use crate::track_cmd::Setup;

/// DejaVu Sans Mono, see `host/assets/LICENSE-DejaVu.txt`.
pub const FONT_BYTES: &[u8] = include_bytes!("../assets/DejaVuSansMono.ttf");

/// The bundled label font.
pub fn font() -> FontRef<'static> {
    // The bytes are a valid TTF compiled into the binary; a parse failure
    // would be caught by every overlay test.
    FontRef::try_from_slice(FONT_BYTES).unwrap_or_else(|_| unreachable!("bundled font parses"))
}

/// Track colours (Tableau 10), chosen by `id % 10`.
const PALETTE: [[u8; 3]; 10] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [188, 189, 34],
    [23, 190, 207],
    [255, 215, 0],
];

/// Colour of untracked objects.
const UNTRACKED: Rgb<u8> = Rgb([150, 150, 150]);

/// The colour of track `id`.
pub fn track_colour(id: u32) -> Rgb<u8> {
    Rgb(PALETTE[(id % PALETTE.len() as u32) as usize])
}

/// One left object of a frame as the overlay draws it.
#[derive(Debug, Clone, PartialEq)]
pub struct Mark {
    /// Counted track that took the object, if any.
    pub track: Option<u32>,
    /// Oriented box, rectified left pixels.
    pub obb: OrientedBox,
    /// Paired right object's upright box, rectified right pixels.
    pub right_box: Option<Roi>,
    /// The right box was found by the epipolar search, not segmented
    /// (`fishtrack_core::epipolar`): drawn thin and labelled `searched`.
    pub searched: bool,
}

/// A frame a track bridged by prediction.
#[derive(Debug, Clone, PartialEq)]
pub struct Predicted {
    /// Track id.
    pub track: u32,
    /// Predicted upright box, rectified left pixels.
    pub bbox: Roi,
}

/// What one frame's overlay shows.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameMarks {
    /// Left objects.
    pub objects: Vec<Mark>,
    /// Predicted track boxes.
    pub predicted: Vec<Predicted>,
}

/// Gathers the per-frame marks from the pipeline's events. Only tracks in
/// `fish` (the counted ones; duplicates are left out) get an id and colour.
pub fn marks_from_events(events: &[PipelineEvent], fish: &[FishOut]) -> BTreeMap<u32, FrameMarks> {
    let counted: BTreeSet<u32> = fish.iter().map(|f| f.track_id).collect();
    let mut owner: BTreeMap<(u32, u16), u32> = BTreeMap::new();
    let mut out: BTreeMap<u32, FrameMarks> = BTreeMap::new();
    for e in events {
        if let PipelineEvent::TrackFrame {
            track,
            frame,
            obs,
            bbox,
            ..
        } = *e
        {
            if !counted.contains(&track) {
                continue;
            }
            match obs {
                Some(i) => {
                    owner.insert((frame, i), track);
                }
                None => out
                    .entry(frame)
                    .or_default()
                    .predicted
                    .push(Predicted { track, bbox }),
            }
        }
    }
    for e in events {
        if let PipelineEvent::Object {
            frame,
            index,
            obb,
            stereo,
            ..
        } = *e
        {
            out.entry(frame).or_default().objects.push(Mark {
                track: owner.get(&(frame, index)).copied(),
                obb,
                right_box: stereo.map(|s| s.right_box),
                searched: stereo.is_some_and(|s| s.pair.searched),
            });
        }
    }
    out
}

/// Line thickness for a frame `width` pixels wide.
fn thickness(width: u32) -> i32 {
    1 + (width / 1024) as i32
}

/// A line `thick` pixels wide (square brush).
fn thick_line(img: &mut RgbImage, a: (f32, f32), b: (f32, f32), c: Rgb<u8>, thick: i32) {
    let lo = -(thick - 1) / 2;
    for dy in lo..lo + thick {
        for dx in lo..lo + thick {
            let (ox, oy) = (dx as f32, dy as f32);
            draw_line_segment_mut(img, (a.0 + ox, a.1 + oy), (b.0 + ox, b.1 + oy), c);
        }
    }
}

fn polygon(img: &mut RgbImage, p: &[(f32, f32); 4], c: Rgb<u8>, thick: i32) {
    for i in 0..4 {
        thick_line(img, p[i], p[(i + 1) % 4], c, thick);
    }
}

/// Corners of an oriented box, shifted by `dx`.
fn obb_corners(b: &OrientedBox, dx: f32) -> [(f32, f32); 4] {
    let (s, c) = (b.angle.sin(), b.angle.cos());
    let (ux, uy) = (c * b.half_w, s * b.half_w);
    let (vx, vy) = (-s * b.half_h, c * b.half_h);
    let (cx, cy) = (b.cx + dx, b.cy);
    [
        (cx - ux - vx, cy - uy - vy),
        (cx + ux - vx, cy + uy - vy),
        (cx + ux + vx, cy + uy + vy),
        (cx - ux + vx, cy - uy + vy),
    ]
}

/// Corners of an upright box (pixel outline), shifted by `dx`.
fn roi_corners(b: &Roi, dx: f32) -> [(f32, f32); 4] {
    let (x0, y0) = (b.x as f32 + dx - 0.5, b.y as f32 - 0.5);
    let (x1, y1) = (x0 + b.w as f32, y0 + b.h as f32);
    [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
}

/// A label with a dark backing box, kept inside the image.
struct Label<'a> {
    font: &'a FontRef<'a>,
    scale: f32,
    /// Labels stay below this row (the header).
    top: i32,
}

fn label(img: &mut RgbImage, l: &Label, x: f32, y: f32, c: Rgb<u8>, t: &str) {
    let (font, scale) = (l.font, l.scale);
    let (tw, th) = text_size(PxScale::from(scale), font, t);
    let x = (x as i32).clamp(0, (img.width() as i32 - tw as i32 - 2).max(0));
    let y = (y as i32 - th as i32 - 3).clamp(
        l.top + 1,
        (img.height() as i32 - th as i32 - 2).max(l.top + 1),
    );
    let rect = imageproc::rect::Rect::at(x - 1, y - 1).of_size(tw + 3, th + 3);
    imageproc::drawing::draw_filled_rect_mut(img, rect, Rgb([0, 0, 0]));
    draw_text_mut(img, c, x, y, PxScale::from(scale), font, t);
}

/// Views wider than this are shrunk by an integer factor (box average)
/// before drawing: a 2048² haul gives 1024-wide views, about 2.5 MB per
/// picture instead of 10.
pub const MAX_VIEW_WIDTH: u32 = 1024;

/// The integer shrink factor for views `w` pixels wide.
pub fn shrink_factor(w: u32) -> u32 {
    w.div_ceil(MAX_VIEW_WIDTH).max(1)
}

/// `img` shrunk by `k` (mean of each `k × k` block; partial blocks at the
/// right and bottom edges are dropped).
fn shrink(img: &GrayImage, k: u32) -> GrayImage {
    if k == 1 {
        return img.clone();
    }
    let (w, h) = (img.width() / k, img.height() / k);
    GrayImage::from_fn(w.max(1), h.max(1), |x, y| {
        let mut sum = 0u32;
        for dy in 0..k {
            for dx in 0..k {
                let (sx, sy) = (
                    (x * k + dx).min(img.width() - 1),
                    (y * k + dy).min(img.height() - 1),
                );
                sum += u32::from(img.get_pixel(sx, sy).0[0]);
            }
        }
        image::Luma([((sum + k * k / 2) / (k * k)) as u8])
    })
}

/// Draws one frame's overlay: rectified `left` | `right` with the marks
/// (shrunk by [`shrink_factor`] when wider than [`MAX_VIEW_WIDTH`]).
/// `lengths` maps counted track ids to their length in mm (if measured).
pub fn render(
    frame: u32,
    left: &GrayImage,
    right: &GrayImage,
    marks: &FrameMarks,
    lengths: &BTreeMap<u32, Option<f64>>,
    font: &FontRef,
) -> RgbImage {
    let k = shrink_factor(left.width());
    let (left, right) = (shrink(left, k), shrink(right, k));
    let (w, h) = left.dimensions();
    let gap = (w / 128).max(4);
    let scale = (w as f32 / 40.0).clamp(11.0, 48.0);
    let header = scale as u32 + 8;
    let total_w = 2 * w + gap;
    let mut img = RgbImage::from_pixel(total_w, h + header, Rgb([0, 0, 0]));
    for (src, x0) in [(&left, 0u32), (&right, w + gap)] {
        for (x, y, p) in src.enumerate_pixels() {
            if x < w && y < h {
                let v = p.0[0];
                img.put_pixel(x0 + x, y + header, Rgb([v, v, v]));
            }
        }
    }
    let thick = thickness(w);
    let dy = header as f32;
    let rx = (w + gap) as f32;
    let kf = k as f32;
    // full-resolution rectified pixels → picture pixels, left or right view
    let at = |(x, y): (f32, f32), x0: f32| ((x + 0.5) / kf - 0.5 + x0, (y + 0.5) / kf - 0.5 + dy);
    let quad = |p: [(f32, f32); 4], x0: f32| p.map(|q| at(q, x0));
    let lab = Label {
        font,
        scale,
        top: header as i32,
    };
    for m in &marks.objects {
        let colour = m.track.map(track_colour).unwrap_or(UNTRACKED);
        let t = if m.track.is_some() { thick } else { 1 };
        polygon(&mut img, &quad(obb_corners(&m.obb, 0.0), 0.0), colour, t);
        if let Some(rb) = &m.right_box {
            let corners = quad(roi_corners(rb, 0.0), rx);
            if m.searched {
                polygon(&mut img, &corners, colour, 1);
                label(
                    &mut img,
                    &lab,
                    corners[0].0,
                    corners[0].1,
                    colour,
                    "searched",
                );
            } else {
                polygon(&mut img, &corners, colour, t);
            }
            let rc = (
                rb.x as f32 + rb.w as f32 / 2.0 - 0.5,
                rb.y as f32 + rb.h as f32 / 2.0 - 0.5,
            );
            thick_line(
                &mut img,
                at((m.obb.cx, m.obb.cy), 0.0),
                at(rc, rx),
                colour,
                1,
            );
        }
    }
    for p in &marks.predicted {
        let c = quad(roi_corners(&p.bbox, 0.0), 0.0);
        polygon(&mut img, &c, track_colour(p.track), 1);
        let t = format!("id {} ?", p.track);
        label(&mut img, &lab, c[0].0, c[0].1, track_colour(p.track), &t);
    }
    for m in &marks.objects {
        let Some(id) = m.track else { continue };
        let text = match lengths.get(&id).copied().flatten() {
            Some(l) => format!("id {id} {l:.0} mm"),
            None => format!("id {id}"),
        };
        let c = quad(obb_corners(&m.obb, 0.0), 0.0);
        let top = c.iter().map(|p| p.1).fold(f32::INFINITY, f32::min);
        let left_x = c.iter().map(|p| p.0).fold(f32::INFINITY, f32::min).max(0.0);
        label(&mut img, &lab, left_x, top, track_colour(id), &text);
    }
    let white = Rgb([255, 255, 255]);
    let shrunk = if k > 1 {
        format!(", 1/{k} scale")
    } else {
        String::new()
    };
    draw_text_mut(
        &mut img,
        white,
        4,
        4,
        PxScale::from(scale),
        font,
        &format!("frame {frame}  left (rectified{shrunk})"),
    );
    draw_text_mut(
        &mut img,
        white,
        (w + gap + 4) as i32,
        4,
        PxScale::from(scale),
        font,
        &format!("right (rectified{shrunk})"),
    );
    img
}

/// Writes `OUT/overlays/NNNNNN.png` for every frame of the haul: frames are
/// re-read and re-rectified (in parallel) once the tracks are known.
pub fn write_all(
    setup: &Setup,
    out: &std::path::Path,
    events: &[PipelineEvent],
    fish: &[FishOut],
) -> anyhow::Result<()> {
    use rayon::prelude::*;
    let dir = out.join("overlays");
    std::fs::create_dir_all(&dir)
        .map_err(|e| InputError::file(&dir, format!("cannot create the directory: {e}")))?;
    crate::survey::remove_partials(&dir);
    let marks = marks_from_events(events, fish);
    let lengths: BTreeMap<u32, Option<f64>> =
        fish.iter().map(|f| (f.track_id, f.length_mm)).collect();
    let font = font();
    let empty = FrameMarks::default();
    let bar = crate::progress::bar(setup.haul.frames.len() as u64, "overlays", "frames");
    setup
        .haul
        .frames
        .par_iter()
        .try_for_each(|pair| -> anyhow::Result<()> {
            let (l, r) = setup.rectified(pair)?;
            let m = marks.get(&pair.index).unwrap_or(&empty);
            let img = render(pair.index, &l, &r, m, &lengths, &font);
            crate::plot::write_png(&dir.join(file_name(pair.index)), &img)?;
            bar.inc(1);
            Ok(())
        })?;
    bar.finish_and_clear();
    Ok(())
}

/// `NNNNNN.png` for frame `index`.
pub fn file_name(index: u32) -> String {
    format!("{index:06}.png")
}

#[cfg(test)]
mod tests {
    use super::*;
    use fishtrack_core::pipeline::StereoInfo;

    fn obb(cx: f32, cy: f32) -> OrientedBox {
        OrientedBox {
            cx,
            cy,
            half_w: 20.0,
            half_h: 6.0,
            angle: 0.3,
        }
    }

    #[test]
    fn wide_views_are_shrunk_and_marks_follow() {
        assert_eq!((shrink_factor(256), shrink_factor(1024)), (1, 1));
        assert_eq!((shrink_factor(1025), shrink_factor(2048)), (2, 2));
        assert_eq!(shrink_factor(4096), 4);
        let (w, h) = (2048u32, 64u32);
        let left = GrayImage::from_fn(w, h, |x, _| image::Luma([if x % 2 == 0 { 10 } else { 30 }]));
        let marks = FrameMarks {
            objects: vec![Mark {
                track: Some(1),
                obb: OrientedBox {
                    cx: 1000.0,
                    cy: 40.0,
                    half_w: 100.0,
                    half_h: 10.0,
                    angle: 0.0,
                },
                right_box: None,
                searched: false,
            }],
            predicted: vec![],
        };
        let img = render(1, &left, &left, &marks, &BTreeMap::new(), &font());
        let header = 25 + 8; // text scale 1024 / 40 px
        assert_eq!(img.dimensions(), (2 * 1024 + 8, 32 + header));
        // 2×2 block mean of 10 and 30
        assert_eq!(*img.get_pixel(3, header + 2), Rgb([20, 20, 20]));
        // the box's bottom edge: y = (40 + 10 + 0.5)/2 − 0.5 = 24.75, at
        // x = 540 (the box spans 450..550; its label covers the left part)
        let c = track_colour(1);
        assert!(
            (24..=26).any(|y| *img.get_pixel(540, header + y) == c),
            "bottom edge"
        );
        assert_ne!(*img.get_pixel(540, header + 20), c);
    }

    #[test]
    fn marks_take_the_counted_tracks_only() {
        let fish = vec![FishOut {
            track_id: 4,
            first_frame: 1,
            last_frame: 2,
            frames: 2,
            length_mm: Some(300.0),
            length_sd_mm: Some(1.0),
            range_mm: None,
        }];
        let roi = Roi {
            x: 10,
            y: 20,
            w: 30,
            h: 10,
        };
        let ev = |frame, index| PipelineEvent::Object {
            frame,
            index,
            bbox: roi,
            obb: obb(50.0, 40.0),
            area: 100,
            stereo: None::<StereoInfo>,
        };
        let tf = |track, frame, obs| PipelineEvent::TrackFrame {
            track,
            frame,
            obs,
            bbox: roi,
            centre: None,
        };
        let events = [
            ev(1, 0),
            ev(1, 1),
            ev(2, 0),
            tf(4, 1, Some(1)),
            tf(9, 1, Some(0)), // track 9 is a duplicate: not in `fish`
            tf(4, 3, None),
        ];
        let m = marks_from_events(&events, &fish);
        let f1 = &m[&1];
        assert_eq!(f1.objects.len(), 2);
        assert_eq!(f1.objects[0].track, None);
        assert_eq!(f1.objects[1].track, Some(4));
        assert_eq!(m[&2].objects[0].track, None);
        assert_eq!(
            m[&3].predicted,
            vec![Predicted {
                track: 4,
                bbox: roi
            }]
        );
    }

    /// Track 3's object at (64, 60) in the left view, paired with the right
    /// box (30, 52, 40 × 16), found by the search or not.
    fn one_mark(searched: bool) -> FrameMarks {
        FrameMarks {
            objects: vec![Mark {
                track: Some(3),
                obb: OrientedBox {
                    cx: 64.0,
                    cy: 60.0,
                    half_w: 20.0,
                    half_h: 8.0,
                    angle: 0.0,
                },
                right_box: Some(Roi {
                    x: 30,
                    y: 52,
                    w: 40,
                    h: 16,
                }),
                searched,
            }],
            predicted: vec![],
        }
    }

    #[test]
    fn render_draws_boxes_in_the_track_colour_on_both_views() {
        let (w, h) = (128u32, 96u32);
        let left = GrayImage::from_pixel(w, h, image::Luma([20]));
        let right = GrayImage::from_pixel(w, h, image::Luma([20]));
        let marks = one_mark(false);
        let lengths = BTreeMap::from([(3, Some(412.4))]);
        let img = render(7, &left, &right, &marks, &lengths, &font());
        let gap = 4;
        let header = 11 + 8;
        assert_eq!(img.dimensions(), (2 * w + gap, h + header));
        let c = track_colour(3);
        // left oriented box: top edge at y = 60 − 8 through x = 64
        assert_eq!(*img.get_pixel(64, 52 + header), c);
        // right upright box: left edge at x = 30 − 0.5 → pixel 29 or 30
        let rx = w + gap;
        let p = |x| *img.get_pixel(rx + x, 60 + header);
        assert!(p(29) == c || p(30) == c);
        // the untouched background keeps its grey
        assert_eq!(*img.get_pixel(5, h + header - 3), Rgb([20, 20, 20]));
        // a label was drawn in the track colour (red, anti-aliased on black)
        // between the header and the box's top edge
        let lit = (header..50 + header)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .filter(|&(x, y)| {
                let [r, g, _] = img.get_pixel(x, y).0;
                r > 80 && g < r / 2
            })
            .count();
        assert!(lit > 10, "label pixels {lit}");
    }

    #[test]
    fn a_searched_right_box_is_labelled_in_the_right_view() {
        let (w, h) = (128u32, 96u32);
        let grey = GrayImage::from_pixel(w, h, image::Luma([20]));
        let lit_right = |searched: bool| {
            let marks = one_mark(searched);
            let img = render(7, &grey, &grey, &marks, &BTreeMap::new(), &font());
            let (rx, header) = (w + 4, 11 + 8);
            // label pixels (the track's red) above the right box
            (header..50 + header)
                .flat_map(|y| (rx..rx + w).map(move |x| (x, y)))
                .filter(|&(x, y)| {
                    let [r, g, _] = img.get_pixel(x, y).0;
                    r > 80 && g < r / 2
                })
                .count()
        };
        assert!(lit_right(true) > 10, "{}", lit_right(true));
        assert_eq!(lit_right(false), 0);
    }
}
