//! Criterion benches of the live view's drawing at 800 × 800 pixels: filling a snapshot
//! from the state (the simulation thread's share of a frame) and drawing it (the
//! rasterizer, with the status line), for the whole box of a dilute random gas of 10⁵,
//! 10⁶ and 10⁷ disks (splatted where a disk is under a pixel), and the 10⁶ gas zoomed
//! 16 times (true circles, most disks off screen). Presenting the pixels to a window is
//! measured by `collide view --stats` itself (`present_ms_mean`), on a display.
//!
//! Throughput is in disks per iteration. Run: `cargo bench --bench view`.

use criterion::{BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};

use collide::draw::raster::{Frame, View, draw, fast_speed};
use collide::sim::Scene;
use collide::sim::scene::GasSpec;
use collide::sim::snapshot::Snapshot;
use collide::view::status::{STATUS_ROWS, StatusFont};

const PIXELS: usize = 800;
/// The seed scene's packing: 5% of the box covered.
const PACKING: f64 = 0.05;

fn gas(n_particles: usize) -> Scene {
    GasSpec {
        seed: 42,
        ..GasSpec::unit(n_particles, PACKING)
    }
    .build()
    .expect("a dilute gas places")
}

fn bench_view(c: &mut Criterion) {
    let font = StatusFont::default();
    let mut group = c.benchmark_group("view");
    group.sample_size(10);
    for n_particles in [100_000, 1_000_000, 10_000_000] {
        let scene = gas(n_particles);
        let fast = fast_speed(&scene.particles);
        let mut snapshot = Snapshot::default();
        group.throughput(Throughput::Elements(n_particles as u64));
        group.bench_function(BenchmarkId::new("snapshot", n_particles), |b| {
            b.iter(|| snapshot.fill_from(&scene.particles, fast))
        });
        let whole = View::whole_box(PIXELS, PIXELS, scene.domain.width, scene.domain.height);
        let mut zoomed = whole;
        zoomed.zoom_by(16.0);
        let mut views = vec![("draw", whole)];
        if n_particles == 1_000_000 {
            views.push(("draw_zoom16", zoomed));
        }
        for (name, view) in views {
            let mut frame = Frame::with_status_rows(STATUS_ROWS);
            group.bench_function(BenchmarkId::new(name, n_particles), |b| {
                b.iter(|| {
                    draw(&snapshot, &view, &mut frame);
                    font.write(&mut frame, "1000 frames/s  1000 steps/s  N 1000000");
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench_view);
criterion_main!(benches);
