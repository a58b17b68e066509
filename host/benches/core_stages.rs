//! Criterion benches of the core stages on synthetic 2048 × 2048 frames
//! (issue 8): mesh removal (Section V.A), the frame noise estimate of the
//! variance test (III.C), the 7 × 7 gradient (III.A), the
//! gradient histogram + threshold, streaming labels, a whole-frame
//! segmentation, the fixed-point remap (IV.A), the whole pipeline on a
//! stereo pair and its length stage (IV.D) alone.
//!
//! `cargo bench -p fishtrack --bench core_stages` (add `-- --quick` for a
//! short run). The frames are procedural, deterministic: noisy water, a
//! bright diagonal mesh in the top and bottom bands and a few textured
//! elliptic fish of different contrast; the right frame is the left one
//! shifted by a disparity of 40 px.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use nalgebra::Matrix3x4;

use fishtrack_core::geometry::StereoGeometry;
use fishtrack_core::hist::add_row_256;
use fishtrack_core::label::{StreamLabeler, RUN_WORDS, SLOT_WORDS};
use fishtrack_core::length::measure_length;
use fishtrack_core::morph::{disk_scratch_len, gradient_disk, remove_mesh, Disk};
use fishtrack_core::object::Objects;
use fishtrack_core::pipeline::{DefaultPipeline, PipelineConfig, REFINE_BLOCKS};
use fishtrack_core::remap::{pack, remap_bilinear, RemapTable};
use fishtrack_core::segment::coarse::gradient_threshold;
use fishtrack_core::segment::{segment_frame, workspace_size, RECOMMENDED_MAX_ROI_PIXELS};
use fishtrack_core::{ImageView, ImageViewMut, Params};

const W: usize = 2048;
const H: usize = 2048;

/// A deterministic synthetic frame (see the module doc).
fn frame(shift: isize) -> Vec<u8> {
    let mut s = 0x9E37_79B9_7F4A_7C15u64;
    let mut noise = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        ((s >> 32) % 13) as i32 - 6
    };
    let fish: [(f32, f32, f32, f32, f32, i32); 6] = [
        (600.0, 900.0, 250.0, 60.0, 0.2, 60),
        (1300.0, 700.0, 180.0, 45.0, -0.4, 30),
        (1000.0, 1400.0, 320.0, 80.0, 0.1, 90),
        (400.0, 1600.0, 120.0, 30.0, 0.8, 20),
        (1700.0, 1200.0, 200.0, 50.0, -0.1, 45),
        (900.0, 400.0, 150.0, 40.0, 0.5, 15),
    ];
    let mut img = vec![0u8; W * H];
    for y in 0..H {
        for x in 0..W {
            let xs = x as isize + shift;
            let mut v = 40 + (x as i32 * 20 / W as i32) + noise();
            let band = !(H / 6..=5 * H / 6).contains(&y);
            if band
                && ((xs + y as isize).rem_euclid(48) < 2 || (xs - y as isize).rem_euclid(48) < 2)
            {
                v += 50;
            }
            for &(cx, cy, a, b, ang, c) in &fish {
                let (dx, dy) = (xs as f32 - cx, y as f32 - cy);
                let (co, si) = (ang.cos(), ang.sin());
                let (u, w) = (dx * co + dy * si, -dx * si + dy * co);
                if (u / a).powi(2) + (w / b).powi(2) <= 1.0 {
                    v += c + ((u * 0.1).sin() * 6.0) as i32;
                }
            }
            img[y * W + x] = v.clamp(0, 255) as u8;
        }
    }
    img
}

fn geometry() -> StereoGeometry {
    let f = 1800.0f32;
    let (cx, cy) = (W as f32 / 2.0, H as f32 / 2.0);
    let p1 = Matrix3x4::new(f, 0.0, cx, 0.0, 0.0, f, cy, 0.0, 0.0, 0.0, 1.0, 0.0);
    let p2 = Matrix3x4::new(f, 0.0, cx, -f * 200.0, 0.0, f, cy, 0.0, 0.0, 0.0, 1.0, 0.0);
    StereoGeometry::from_projections(&p1, &p2).expect("synthetic rig")
}

fn benches(c: &mut Criterion) {
    let left = frame(0);
    let right = frame(40);
    let lv = ImageView::packed(&left, W, H).unwrap();
    let rv = ImageView::packed(&right, W, H).unwrap();
    let params = Params::for_frame(W as u32);
    let disk = Disk::opencv_ellipse(params.disk_size);
    let mut g = c.benchmark_group("core_2048");
    g.sample_size(10);
    g.throughput(Throughput::Elements((W * H) as u64));

    let (mut tmp, mut out) = (vec![0u8; W * H], vec![0u8; W * H]);
    g.bench_function("mesh_removal", |b| {
        b.iter(|| remove_mesh(black_box(lv), 7, &mut tmp, &mut out).unwrap())
    });
    g.bench_function("noise_sigma", |b| {
        b.iter(|| fishtrack_core::noise::noise_sigma16(black_box(lv)))
    });
    let filtered = out.clone();
    let fv = ImageView::packed(&filtered, W, H).unwrap();
    let mut scratch = vec![0u8; disk_scratch_len(W, 15)];
    let mut grad = vec![0u8; W * H];
    g.bench_function("gradient_7x7", |b| {
        b.iter(|| gradient_disk(black_box(fv), &disk, &mut grad, &mut scratch).unwrap())
    });
    g.bench_function("histogram_threshold", |b| {
        b.iter(|| {
            let mut hist = [0u32; 256];
            for row in grad.chunks_exact(W) {
                add_row_256(&mut hist, black_box(row));
            }
            gradient_threshold(&hist)
        })
    });
    let t = {
        let mut hist = [0u32; 256];
        for row in grad.chunks_exact(W) {
            add_row_256(&mut hist, row);
        }
        gradient_threshold(&hist)
    };
    let (tl, rl) = (StreamLabeler::table_len(W), StreamLabeler::runs_len(W));
    let (mut slots, mut free) = (vec![[0u64; SLOT_WORDS]; tl], vec![0u32; tl]);
    let (mut prev, mut cur) = (vec![[0u32; RUN_WORDS]; rl], vec![[0u32; RUN_WORDS]; rl]);
    g.bench_function("stream_labels", |b| {
        b.iter(|| {
            let mut sl = StreamLabeler::new(W, &mut slots, &mut free, &mut prev, &mut cur).unwrap();
            let mut n = 0usize;
            for row in grad.chunks_exact(W) {
                sl.push_row_above(black_box(row), t, |_| n += 1);
            }
            sl.finish(|_| n += 1);
            n
        })
    });
    let mut ws = vec![0u8; workspace_size(W, H, RECOMMENDED_MAX_ROI_PIXELS)];
    let mut objs: Box<Objects<64, 16384>> = Box::new(Objects::new());
    g.bench_function("segment_frame", |b| {
        b.iter(|| segment_frame(black_box(lv), &params, &mut ws, &mut objs).unwrap())
    });
    // a mild barrel-distortion-like table
    let (mut xy, mut fr) = (vec![0i16; 2 * W * H], vec![0u16; W * H]);
    for y in 0..H {
        for x in 0..W {
            let (dx, dy) = (x as f32 - 1024.0, y as f32 - 1024.0);
            let k = 1.0 + 2e-8 * (dx * dx + dy * dy);
            let (sx, sy) = (1024.0 + dx * k, 1024.0 + dy * k);
            let (p, f) = pack((sx * 32.0).round() as i32, (sy * 32.0).round() as i32);
            xy[2 * (y * W + x)] = p[0];
            xy[2 * (y * W + x) + 1] = p[1];
            fr[y * W + x] = f;
        }
    }
    let table = RemapTable::new(W, H, &xy, &fr).unwrap();
    let mut dst = vec![0u8; W * H];
    g.bench_function("remap_bilinear", |b| {
        b.iter(|| {
            let mut d = ImageViewMut::packed(&mut dst, W, H).unwrap();
            remap_bilinear(black_box(&lv), &table, &mut d).unwrap()
        })
    });
    g.finish();

    let mut g = c.benchmark_group("pipeline_2048_pair");
    g.sample_size(10);
    g.throughput(Throughput::Elements(1));
    let cfg = PipelineConfig::new(params, geometry(), W as u32, H as u32);
    let mut ws = vec![0u8; DefaultPipeline::workspace_size(W, H)];
    let mut pipe = Box::new(DefaultPipeline::new(cfg).unwrap());
    let mut frame_no = 0u32;
    g.bench_function("process_frame", |b| {
        b.iter(|| {
            frame_no += 1;
            pipe.process_frame(frame_no, black_box(lv), black_box(rv), &mut ws, &mut |_| {})
                .unwrap()
        })
    });
    // the length stage (IV.D) alone, on the pairs of the frame just processed;
    // `length_stage_every_end`: without the probe gate (a snake at every end,
    // as before the gate)
    frame_no += 1;
    pipe.process_frame(frame_no, lv, rv, &mut ws, &mut |_| {})
        .unwrap();
    let lcfg = PipelineConfig::new(params, geometry(), W as u32, H as u32);
    let mut every = lcfg;
    every.length.probe_gate = false;
    // `length_stage_block_line`: without session 30's slanted fit and fin
    // profile (the block line alone, as before)
    let mut block_line = lcfg;
    block_line.length.slant_fit = false;
    block_line.length.fin_profile = false;
    for (name, lcfg) in [
        ("length_stage", lcfg),
        ("length_stage_every_end", every),
        ("length_stage_block_line", block_line),
    ] {
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut total = 0.0f32;
                for p in pipe.pairs().pairs.iter() {
                    if let Ok(l) = measure_length::<_, _, REFINE_BLOCKS>(
                        black_box(&lv),
                        black_box(&rv),
                        pipe.left_objects(),
                        pipe.right_objects(),
                        p,
                        &lcfg.geometry,
                        &lcfg.params,
                        &lcfg.length,
                    ) {
                        total += l.length_mm;
                    }
                }
                total
            })
        });
    }
    g.finish();
}

criterion_group!(core_stages, benches);
criterion_main!(core_stages);
