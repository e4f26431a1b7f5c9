//! The shared context: one per process, usable from several threads, reopened after its device
//! was lost.

use super::*;

#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored only (scripts/test.sh does when one exists)"]
fn shared_context_is_reused_across_threads() {
    let first = GpuContext::with_shared(|ctx| std::sync::Arc::as_ptr(ctx) as usize).expect("GPU test run without a usable adapter");
    let others: Vec<usize> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..4).map(|_| s.spawn(|| GpuContext::with_shared(|ctx| std::sync::Arc::as_ptr(ctx) as usize).unwrap())).collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    assert!(others.iter().all(|&p| p == first), "a second context was opened");
}

#[test]
#[ignore = "needs a GPU adapter: run with --run-ignored only (scripts/test.sh does when one exists)"]
fn shared_context_is_reopened_after_device_loss() {
    let lost = GpuContext::with_shared(|ctx| {
        ctx.device.destroy();
        let _ = ctx.device.poll(wgpu::PollType::Wait);
        (ctx.is_lost(), std::sync::Arc::as_ptr(ctx) as usize)
    })
    .expect("GPU test run without a usable adapter");
    assert!(lost.0, "destroying the device should report it lost");
    // The next caller gets a working context: a buffer round trip succeeds.
    let data = GpuContext::with_shared(|ctx| {
        assert!(!ctx.is_lost());
        let buf = ctx.storage_buffer("probe", bytemuck::cast_slice(&[1.0f32, 2.0, 3.0, 4.0])).unwrap();
        ctx.read_buffer(&buf, 16).unwrap()
    })
    .unwrap();
    assert_eq!(bytemuck::cast_slice::<u8, f32>(&data), &[1.0, 2.0, 3.0, 4.0]);
}
