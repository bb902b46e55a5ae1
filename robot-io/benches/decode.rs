//! Decoding an RTDE data package of 150 fields (the fields of a real ur_rtde recording, the
//! RAD UR3e trace, topped up with input registers), as the client's reader and consumer do
//! per package: frame decode, recipe check, every field into a caller-owned buffer.
//!
//! Criterion reports the mean; the bench also times single decodes with `Instant` and prints
//! the median, p99 and worst (which include ~20–40 ns of `Instant` overhead).

use std::hint::black_box;
use std::time::Instant;

use criterion::{Criterion, criterion_group, criterion_main};
use robot_io::codec::{ControllerPackage, FieldType, Recipe, Value, known_field_type};

const FIELDS: usize = 150;

fn recipe_and_package() -> (Recipe, Vec<u8>) {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../data/rtde-traces/ur3e_25hz_rad_segment_L0L1.csv"
    );
    let header = std::fs::read_to_string(path)
        .map(|t| t.lines().next().unwrap_or_default().to_owned())
        .unwrap_or_default();
    let mut names: Vec<String> = Vec::new();
    for col in header.split(',') {
        let base = if known_field_type(col).is_some() {
            col.to_owned()
        } else {
            col.rsplit_once('_')
                .map(|(b, _)| b.to_owned())
                .unwrap_or_default()
        };
        if known_field_type(&base).is_some() && !names.contains(&base) {
            names.push(base);
        }
    }
    let mut i = 0;
    while names.len() < FIELDS {
        names.push(format!("input_double_register_{i}"));
        i += 1;
    }
    names.truncate(FIELDS);
    let types: Vec<FieldType> = names
        .iter()
        .map(|n| known_field_type(n).unwrap_or(FieldType::Double))
        .collect();
    let refs: Vec<&str> = names.iter().map(String::as_str).collect();
    let recipe = Recipe::new(1, &refs, &types).expect("recipe");
    let values: Vec<Value> = types
        .iter()
        .enumerate()
        .map(|(k, t)| Value::from_components(*t, &[k as f64 * 0.1, 1.5, -2.25, 3.0, 4.0, 5.0]))
        .collect();
    let mut pkg = Vec::new();
    recipe.encode_values(&values, &mut pkg).expect("encode");
    (recipe, pkg)
}

fn decode(recipe: &Recipe, pkg: &[u8], out: &mut [Value]) {
    if let Ok(ControllerPackage::Data(d)) = ControllerPackage::decode(pkg)
        && let Ok(payload) = recipe.check(&d)
    {
        let _ = recipe.decode_into(payload, out);
    }
}

fn bench(c: &mut Criterion) {
    let (recipe, pkg) = recipe_and_package();
    let mut out = vec![Value::Double(0.0); recipe.len()];
    println!(
        "package: {} fields, {} scalar values, {} bytes",
        recipe.len(),
        recipe.slots().iter().map(|s| s.ty.width()).sum::<usize>(),
        pkg.len()
    );

    // Single-decode timings for the tail.
    let n = 200_000;
    let mut ns = Vec::with_capacity(n);
    for _ in 0..10_000 {
        decode(&recipe, black_box(&pkg), &mut out);
    }
    for _ in 0..n {
        let t = Instant::now();
        decode(&recipe, black_box(&pkg), &mut out);
        ns.push(t.elapsed().as_nanos() as u64);
        black_box(&out);
    }
    ns.sort_unstable();
    let pct = |p: f64| ns[((n as f64 - 1.0) * p) as usize];
    println!(
        "decode {} fields, {n} single timings: median {} ns, p99 {} ns, worst {} ns (budget 2 000 000 ns)",
        recipe.len(),
        pct(0.5),
        pct(0.99),
        ns[n - 1]
    );

    c.bench_function("decode_data_package_150_fields", |b| {
        b.iter(|| decode(&recipe, black_box(&pkg), &mut out))
    });
}

criterion_group! {
    name = benches;
    config = Criterion::default().sample_size(20).measurement_time(std::time::Duration::from_secs(2)).warm_up_time(std::time::Duration::from_millis(500));
    targets = bench
}
criterion_main!(benches);
