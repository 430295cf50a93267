//! Bare-metal image for `aarch64-unknown-none` on QEMU's `virt` board (Cortex-A72 or A76, EL1,
//! MMU off, one core): checks its fast int8 kernels (NEON; the `sdot` 1×1 GEMM where the CPU has
//! the dot products, as the A76 does) against the reference kernels
//! (`kernel_check`, exit status 1 on a difference), runs the embedded stereo frames through
//! `Localiser` twice, geometric and
//! then semantic (int8 network, semantic ORB, EM association), prints the report of
//! `semloc_firmware_sim::report` through ARM semihosting, then exits QEMU with status 0 when
//! the tracker tracked in both passes, 2 when it did not, 1 on an error and 101 on a panic.
//!
//! ```text
//! cargo build --release -p semloc-firmware-sim --target aarch64-unknown-none --bin qemu_aarch64
//! qemu-system-aarch64 -M virt -cpu cortex-a72 -m 512M -nographic \
//!     -semihosting-config enable=on,target=native \
//!     -kernel target/aarch64-unknown-none/release/qemu_aarch64
//! ```
//!
//! Memory map (`qemu_virt.ld`): code, constants (the embedded frames) and data from
//! `0x4008_0000`, then `.bss` (the ≈ 22 MiB `Localiser` and the network's ≈ 2.5 MiB
//! buffers, zeroed by `_start`), then a 320 MiB
//! stack that `_start` paints so the peak use can be reported. Lines starting with `@` are
//! this target's own (timings from the generic timer, stack peak); the rest is the same text
//! the host prints.
//!
//! On any other target this binary is a stub that says so: the crate's bins are built by
//! `cargo test/clippy --workspace --all-targets` on the host.
#![cfg_attr(all(target_arch = "aarch64", target_os = "none"), no_std, no_main)]
// The crate's only unsafe code: start-up assembly, semihosting traps, the static slot and the
// stack scan. Each block says why it is sound.
#![cfg_attr(all(target_arch = "aarch64", target_os = "none"), allow(unsafe_code))]

#[cfg(not(all(target_arch = "aarch64", target_os = "none")))]
fn main() {
    eprintln!(
        "qemu_aarch64 is a bare-metal image: build it with `--target aarch64-unknown-none` and \
         run it under qemu-system-aarch64 (see firmware-sim/README.md)"
    );
    std::process::exit(2);
}

#[cfg(all(target_arch = "aarch64", target_os = "none"))]
mod fw {
    use core::arch::{asm, global_asm};
    use core::cell::UnsafeCell;
    use core::fmt::{self, Write};
    use core::mem::MaybeUninit;

    use semloc_firmware_sim::core_crate::nn::arm64::dotprod_enabled;
    use semloc_firmware_sim::core_crate::seg::WeightScheme;
    use semloc_firmware_sim::core_crate::tracker::TrackerParams;
    use semloc_firmware_sim::embedded::{HEIGHT, MODEL_BLOB, WIDTH};
    use semloc_firmware_sim::kernel_check::{self, KernelCheckBuffers};
    use semloc_firmware_sim::report::{self, RunSummary};
    use semloc_firmware_sim::{
        embedded_localiser, geometric_params, semantic_params, Localiser, LocaliserError, Network,
        SegStorage, SEMANTIC_SCHEME,
    };

    /// Value `_start` fills the stack with (see [`stack_peak_bytes`]).
    const STACK_PAINT: u64 = 0x5a5a_5a5a_5a5a_5a5a;

    // Entry from QEMU (`-kernel` ELF: PC = _start at EL1, MMU and caches off). Only core 0
    // runs; others (with `-smp > 1`) park. SP goes to the top of the linker script's stack,
    // FP/SIMD is enabled (CPACR_EL1.FPEN = 0b11: no traps at EL0/EL1; Rust code uses the
    // FP/NEON registers everywhere), .bss is zeroed, the stack painted, then Rust runs.
    global_asm!(
        ".section .text._start, \"ax\"",
        ".global _start",
        "_start:",
        "    mrs x0, mpidr_el1",
        "    and x0, x0, #0xff",
        "    cbz x0, 2f",
        "1:  wfe",
        "    b 1b",
        "2:  ldr x0, =__stack_top",
        "    mov sp, x0",
        "    mov x0, #(3 << 20)",
        "    msr cpacr_el1, x0",
        "    isb",
        "    ldr x0, =__bss_start",
        "    ldr x1, =__bss_end",
        "3:  cmp x0, x1",
        "    b.hs 4f",
        "    str xzr, [x0], #8",
        "    b 3b",
        "4:  ldr x0, =__stack_bottom",
        "    ldr x1, =__stack_top",
        "    ldr x2, ={paint}",
        "5:  cmp x0, x1",
        "    b.hs 6f",
        "    str x2, [x0], #8",
        "    b 5b",
        "6:  bl rust_main",
        "7:  wfe",
        "    b 7b",
        paint = const STACK_PAINT,
    );

    extern "C" {
        static __stack_bottom: u8;
        static __stack_top: u8;
    }

    /// ARM semihosting operation numbers (ARM DUI 0471, "Semihosting operations").
    const SYS_WRITE0: usize = 0x04;
    const SYS_EXIT: usize = 0x18;
    /// `ADP_Stopped_ApplicationExit`: SYS_EXIT reason for a normal exit with a status.
    const ADP_STOPPED_APPLICATION_EXIT: usize = 0x20026;

    /// One semihosting call: operation in `w0`, argument (a pointer) in `x1`, `hlt #0xf000`.
    fn semihost(op: usize, arg: usize) -> usize {
        let ret;
        // SAFETY: `hlt #0xf000` traps to the debugger/QEMU semihosting handler, which reads
        // the operation and parameter block and writes only x0; every caller passes a pointer
        // to memory that stays valid and unchanged for the call.
        unsafe {
            asm!("hlt #0xf000", inout("x0") op => ret, in("x1") arg, options(nostack));
        }
        ret
    }

    /// Stops QEMU with `status` (SYS_EXIT with an AArch64 parameter block).
    fn exit(status: u32) -> ! {
        let block = [ADP_STOPPED_APPLICATION_EXIT, status as usize];
        semihost(SYS_EXIT, block.as_ptr() as usize);
        // Only reached without semihosting: park.
        loop {
            // SAFETY: `wfe` only waits for an event; it touches no memory.
            unsafe { asm!("wfe", options(nomem, nostack)) };
        }
    }

    /// Line-buffered semihosting console (SYS_WRITE0 per line: one trap per line, not per
    /// character).
    struct Console {
        buf: [u8; 512],
        len: usize,
    }

    impl Console {
        const fn new() -> Self {
            Self { buf: [0; 512], len: 0 }
        }

        fn flush(&mut self) {
            if self.len > 0 {
                self.buf[self.len] = 0;
                semihost(SYS_WRITE0, self.buf.as_ptr() as usize);
                self.len = 0;
            }
        }
    }

    impl Write for Console {
        fn write_str(&mut self, s: &str) -> fmt::Result {
            for &b in s.as_bytes() {
                // NUL would end SYS_WRITE0's string early; the report never contains one.
                let b = if b == 0 { b'?' } else { b };
                self.buf[self.len] = b;
                self.len += 1;
                if b == b'\n' || self.len == self.buf.len() - 1 {
                    self.flush();
                }
            }
            Ok(())
        }
    }

    /// Generic timer: (count, frequency in Hz).
    fn counter() -> (u64, u64) {
        let (cnt, frq): (u64, u64);
        // SAFETY: reading CNTVCT_EL0/CNTFRQ_EL0 has no side effects; EL1 may access both.
        unsafe {
            asm!("isb", "mrs {c}, cntvct_el0", "mrs {f}, cntfrq_el0",
                 c = out(reg) cnt, f = out(reg) frq, options(nomem, nostack));
        }
        (cnt, frq.max(1))
    }

    fn ms_since(t0: u64) -> f64 {
        let (now, frq) = counter();
        now.wrapping_sub(t0) as f64 * 1e3 / frq as f64
    }

    /// Deepest stack use so far: bytes from the top down to the lowest word that no longer
    /// holds [`STACK_PAINT`].
    fn stack_peak_bytes() -> usize {
        // Both symbols come from the linker script and bound the stack region; only their
        // addresses are taken (safe for extern statics).
        let bottom = core::ptr::addr_of!(__stack_bottom) as usize;
        let top = core::ptr::addr_of!(__stack_top) as usize;
        let mut p = bottom;
        while p < top {
            // SAFETY: `p` is 8-aligned (the region is 16-aligned) and inside the stack region,
            // which is mapped RAM; the words below the live frames are owned by no Rust
            // object, and a volatile read of the live ones only observes them.
            let v = unsafe { core::ptr::read_volatile(p as *const u64) };
            if v != STACK_PAINT {
                break;
            }
            p += 8;
        }
        top - p
    }

    /// Paints the unused stack again (from the bottom up to 256 bytes below the current SP),
    /// so that a later [`stack_peak_bytes`] measures only what runs after this call.
    /// Returns the SP at the call.
    fn repaint_stack() -> usize {
        let bottom = core::ptr::addr_of!(__stack_bottom) as usize;
        let sp: usize;
        // SAFETY: only the words between the stack bottom and 256 bytes below SP are
        // written; AArch64 has no red zone, so no live data sits below SP, and no Rust object
        // lives there. The asm uses only the scratch registers it declares.
        unsafe {
            asm!(
                "mov {sp}, sp",
                "sub {end}, {sp}, #256",
                "2: cmp {p}, {end}",
                "b.hs 3f",
                "str {v}, [{p}], #8",
                "b 2b",
                "3:",
                p = inout(reg) bottom => _,
                sp = out(reg) sp,
                end = out(reg) _,
                v = in(reg) STACK_PAINT,
                options(nostack),
            );
        }
        sp
    }

    /// Where the localiser lives: `.bss`, zeroed by `_start`, never on the stack.
    struct Slot(UnsafeCell<MaybeUninit<Result<Localiser, LocaliserError>>>);

    // SAFETY: one core, no interrupts, and only `build` (below) touches the slot, handing out
    // one live reference at a time.
    unsafe impl Sync for Slot {}

    static LOCALISER: Slot = Slot(UnsafeCell::new(MaybeUninit::uninit()));

    /// The segmentation network's buffers (≈ 2.5 MiB of zeros: `.bss`).
    struct SegSlot(UnsafeCell<SegStorage>);

    // SAFETY: as `Slot`; only `rust_main` takes a reference, once.
    unsafe impl Sync for SegSlot {}

    static SEG_STORAGE: SegSlot = SegSlot(UnsafeCell::new(SegStorage::new()));

    /// The kernel check's buffers (≈ 168 KB of zeros: `.bss`).
    struct CheckSlot(UnsafeCell<KernelCheckBuffers>);

    // SAFETY: as `Slot`; only `rust_main` takes a reference, once.
    unsafe impl Sync for CheckSlot {}

    static CHECK_BUFFERS: CheckSlot = CheckSlot(UnsafeCell::new(KernelCheckBuffers::new()));

    /// Seed and cases per op family of the kernel check (`kernel_check`).
    const CHECK_SEED: u64 = 0x5e10_c0de;
    const CHECK_CASES: u32 = 500;

    /// Builds a localiser with `params` and `semantics` in its static slot, replacing the previous one. Not
    /// inlined: the by-value temporaries of the constructors (tens of MiB at worst) are in
    /// this frame, popped before frames run.
    #[inline(never)]
    fn build(
        con: &mut Console,
        params: TrackerParams,
        semantics: Option<WeightScheme>,
    ) -> &'static mut Localiser {
        // SAFETY: see `Slot`: callers drop the reference of the previous call before calling
        // again (`rust_main` uses each one for one pass only), so no two live references to
        // the slot exist.
        let slot = unsafe { &mut *LOCALISER.0.get() };
        // Written straight into the static slot (the Result around it lives there too).
        match slot.write(embedded_localiser(params, semantics)) {
            Ok(l) => l,
            Err(e) => {
                let _ = writeln!(con, "error: {e}");
                con.flush();
                exit(1)
            }
        }
    }

    /// One pass over the embedded frames with per-frame `@` timings; `None` on an error (printed).
    fn pass(
        con: &mut Console,
        loc: &mut Localiser,
        network: Option<&mut Network<'_>>,
        name: &str,
    ) -> Option<RunSummary> {
        let top = core::ptr::addr_of!(__stack_top) as usize;
        let base = top - repaint_stack();
        let t0 = counter().0;
        let mut last = t0;
        let run = report::run_embedded(loc, network, con, |out, i| {
            let ms = ms_since(last);
            last = counter().0;
            writeln!(out, "@ frame {i} {ms:.1} ms")
        });
        match run {
            Ok(s) => {
                let _ = writeln!(
                    con,
                    "@ {name} pass {:.1} ms, frame stack peak {} bytes, tracked {}",
                    ms_since(t0),
                    stack_peak_bytes().saturating_sub(base),
                    s.tracked()
                );
                Some(s)
            }
            Err(e) => {
                let _ = writeln!(con, "error: {e}");
                None
            }
        }
    }

    #[no_mangle]
    extern "C" fn rust_main() -> ! {
        let mut con = Console::new();
        let (t0, frq) = counter();
        // SAFETY: see `CheckSlot`: the only reference to the buffers ever made.
        let check = unsafe { &mut *CHECK_BUFFERS.0.get() };
        match kernel_check::run(check, CHECK_SEED, CHECK_CASES) {
            Ok(r) => {
                let _ = writeln!(
                    con,
                    "@ kernels: {} 1x1 ({}), {} depthwise, {} first-layer convs, {} resizes and \
                     {} adds bit-equal to the reference, {:.1} ms",
                    r.pointwise,
                    if dotprod_enabled() { "sdot" } else { "NEON" },
                    r.depthwise,
                    r.first_conv,
                    r.resize,
                    r.add,
                    ms_since(t0)
                );
            }
            Err(e) => {
                let _ = writeln!(con, "error: {e}");
                con.flush();
                exit(1)
            }
        }
        let (t0, _) = counter();
        let loc = build(&mut con, geometric_params(), None);
        let _ = writeln!(
            con,
            "@ aarch64 bare metal: localiser {} bytes in .bss, timer {} Hz, init {:.1} ms, \
             construction stack peak {} bytes",
            Localiser::MEMORY_BYTES,
            frq,
            ms_since(t0),
            stack_peak_bytes()
        );
        let geometric = pass(&mut con, loc, None, "geometric");

        let loc = build(&mut con, semantic_params(), Some(SEMANTIC_SCHEME));
        // SAFETY: see `SegSlot`: the only reference to the storage ever made.
        let storage = unsafe { &mut *SEG_STORAGE.0.get() };
        let semantic = match Network::new(MODEL_BLOB, WIDTH, HEIGHT, storage.memory()) {
            Ok(mut net) => pass(&mut con, loc, Some(&mut net), "semantic"),
            Err(e) => {
                let _ = writeln!(con, "error: {e}");
                None
            }
        };
        let code = match (geometric, semantic) {
            (Some(g), Some(s)) if g.tracked() && s.tracked() => 0,
            (Some(_), Some(_)) => 2,
            _ => 1,
        };
        let _ = writeln!(con, "@ total {:.1} ms, exit status {code}", ms_since(t0));
        con.flush();
        exit(code)
    }

    #[panic_handler]
    fn panic(info: &core::panic::PanicInfo<'_>) -> ! {
        let mut con = Console::new();
        let _ = writeln!(con, "panic: {info}");
        con.flush();
        exit(101)
    }
}
