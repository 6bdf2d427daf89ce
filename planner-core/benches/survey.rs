//! Survey planning time against the number of no-fly zones: decomposition,
//! coverage and the UAV route for a 4 km × 4 km ROI with 1, 10, 100 and
//! 1000 NFZs (`cargo bench -p planner-core`). Each stage is also timed on
//! its own so the scaling of each is visible.

use std::hint::black_box;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use geo_types::{Coord, MultiPolygon, Polygon, polygon};
use planner_core::coverage::{self, CellPlan};
use planner_core::decompose;
use planner_core::flock::{ObstacleMap, plan_tour};

mod area;

use area::{SIDE_M, nfzs};
const SPACING_M: f64 = 27.0;

fn roi() -> Polygon<f64> {
    polygon![(x: 0.0, y: 0.0), (x: SIDE_M, y: 0.0), (x: SIDE_M, y: SIDE_M), (x: 0.0, y: SIDE_M)]
}

/// Plans every cell, indexing the free space once (as the survey does).
fn cover(cells: &[Polygon<f64>], free: &MultiPolygon<f64>) -> Vec<CellPlan> {
    let free = coverage::FreeSpace::new(free);
    cells
        .iter()
        .enumerate()
        .filter_map(|(i, c)| coverage::plan_cell_in(i, c, &free, SPACING_M, 0.0))
        .collect()
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("survey");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(10));
    let roi = roi();
    for n in [1usize, 10, 100, 1000] {
        let nfz = nfzs(n);
        let free = decompose::free_space(&roi, &nfz);
        let cells = decompose::decompose(&free, 0.0).unwrap();
        let plans = cover(&cells, &free);
        let obstacles = ObstacleMap::new(&MultiPolygon(nfz.clone()), 2.0);
        let start = Coord { x: -50.0, y: -50.0 };
        eprintln!(
            "{n} NFZs: {} cells, {} lanes",
            cells.len(),
            plans.iter().map(|p| p.lanes.len()).sum::<usize>()
        );

        group.bench_with_input(BenchmarkId::new("decompose", n), &n, |b, _| {
            b.iter(|| {
                decompose::decompose(black_box(&decompose::free_space(&roi, &nfz)), 0.0).unwrap()
            })
        });
        group.bench_with_input(BenchmarkId::new("coverage", n), &n, |b, _| {
            b.iter(|| cover(black_box(&cells), &free))
        });
        group.bench_with_input(BenchmarkId::new("route", n), &n, |b, _| {
            b.iter(|| plan_tour(start, black_box(&plans), &cells, &free, &obstacles).unwrap())
        });
        group.bench_with_input(BenchmarkId::new("all", n), &n, |b, _| {
            b.iter(|| {
                let free = decompose::free_space(&roi, &nfz);
                let cells = decompose::decompose(&free, 0.0).unwrap();
                let plans = cover(&cells, &free);
                let obstacles = ObstacleMap::new(&MultiPolygon(nfz.clone()), 2.0);
                plan_tour(start, &plans, &cells, &free, &obstacles).unwrap()
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
