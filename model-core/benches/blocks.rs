//! One call of each building block, in f32 (the target's type) and Q32.32 fixed point.
//! `cargo bench -p model-core --bench blocks`
use criterion::{black_box, criterion_group, criterion_main, Criterion};
use model_core::delay::DelayLine;
use model_core::lut::Lut2;
use model_core::peak_hold::{plan, SolenoidParams};
use model_core::pwm_comp::PwmCompensator;
use model_core::{Real, Q32};

fn bench_type<R: Real>(c: &mut Criterion) {
    let name = R::NAME;
    let comp = PwmCompensator::<R>::new(13.5, 6.0, 0.0, 100.0).expect("valid");
    c.bench_function(&format!("pwm_comp/{name}"), |b| {
        b.iter(|| comp.apply(black_box(R::from_f64(40.0)), black_box(R::from_f64(12.3))))
    });
    let p = SolenoidParams::pilot_default();
    c.bench_function(&format!("peak_hold_plan/{name}"), |b| {
        b.iter(|| plan::<R>(&p, black_box(R::from_f64(12.3))))
    });
    let mut d = DelayLine::<R, 64>::new(R::ZERO);
    c.bench_function(&format!("delay_push_get/{name}"), |b| {
        b.iter(|| {
            d.push(black_box(R::ONE));
            d.get(black_box(R::from_f64(17.3)))
        })
    });
    let t = Lut2::<R, 4, 4>::new([5.0, 6.0, 7.0, 8.0], [-20.0, 22.0, 60.0, 100.0], [[1.0; 4]; 4]).expect("valid");
    c.bench_function(&format!("lut2_eval/{name}"), |b| {
        b.iter(|| t.eval(black_box(R::from_f64(6.4)), black_box(R::from_f64(31.0))))
    });
}

fn benches(c: &mut Criterion) {
    bench_type::<f32>(c);
    bench_type::<Q32>(c);
}

criterion_group!(blocks, benches);
criterion_main!(blocks);
