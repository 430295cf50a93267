//! A Cortex-M7 (`thumbv7em-none-eabihf`) link of the firmware code (the semantic pipeline:
//! int8 network, semantic ORB, stereo, tracker with EM), made only to measure what it costs on
//! a microcontroller-class target: `.text` (code), `.rodata` (constants, the network blob
//! included), `.bss` (the `Localiser`, the network's buffers and one camera frame buffer).
//! Not run anywhere.
//!
//! ```text
//! cargo build --release -p semloc-firmware-sim --target thumbv7em-none-eabihf --bin thumbv7em_size
//! python3 firmware-sim/elf_sizes.py target/thumbv7em-none-eabihf/release/thumbv7em_size
//! ```
//!
//! Unlike the QEMU image it embeds no frames: the stereo pair arrives in a `.bss` buffer (as
//! from a camera DMA), so `.rodata` holds the network blob and the code's own constants. The memory map of
//! `thumbv7em.ld` is fictional; only the section sizes mean anything.
//!
//! On any other target this binary is a stub that says so.
#![cfg_attr(all(target_arch = "arm", target_os = "none"), no_std, no_main)]
// Only the reset entry, the static slots and the panic handler: see each SAFETY comment.
#![cfg_attr(all(target_arch = "arm", target_os = "none"), allow(unsafe_code))]

#[cfg(not(all(target_arch = "arm", target_os = "none")))]
fn main() {
    eprintln!(
        "thumbv7em_size is a size probe: build it with `--target thumbv7em-none-eabihf` \
         (see firmware-sim/README.md)"
    );
    std::process::exit(2);
}

#[cfg(all(target_arch = "arm", target_os = "none"))]
mod probe {
    use core::cell::UnsafeCell;
    use core::hint::black_box;
    use core::mem::MaybeUninit;

    use semloc_firmware_sim::embedded::{CAMERA, HEIGHT, MODEL_BLOB, WIDTH};
    use semloc_firmware_sim::{
        semantic_params, Localiser, LocaliserConfig, LocaliserError, Network, SegStorage,
        SEMANTIC_SCHEME,
    };

    const PIXELS: usize = WIDTH * HEIGHT;

    /// The localiser's home in `.bss`.
    struct Slot(UnsafeCell<MaybeUninit<Result<Localiser, LocaliserError>>>);
    // SAFETY: single core, no interrupts; `Reset` is the only code touching the statics, and
    // takes one reference to each, once.
    unsafe impl Sync for Slot {}
    static LOCALISER: Slot = Slot(UnsafeCell::new(MaybeUninit::uninit()));

    /// The network's buffers in `.bss`.
    struct SegSlot(UnsafeCell<SegStorage>);
    // SAFETY: as `Slot`.
    unsafe impl Sync for SegSlot {}
    static SEG_STORAGE: SegSlot = SegSlot(UnsafeCell::new(SegStorage::new()));

    /// Left then right luma of one frame, written by the (imagined) camera DMA.
    struct Frames(UnsafeCell<[u8; 2 * PIXELS]>);
    // SAFETY: as `Slot`.
    unsafe impl Sync for Frames {}
    static CAMERA_BUF: Frames = Frames(UnsafeCell::new([0; 2 * PIXELS]));

    fn halt() -> ! {
        loop {
            core::hint::spin_loop();
        }
    }

    #[no_mangle]
    pub extern "C" fn Reset() -> ! {
        // SAFETY: see `Slot`: these are the only references to the statics ever made.
        let (slot, storage, buf) =
            unsafe { (&mut *LOCALISER.0.get(), &mut *SEG_STORAGE.0.get(), &*CAMERA_BUF.0.get()) };
        let config = LocaliserConfig {
            tracker: semantic_params(),
            semantics: Some(SEMANTIC_SCHEME),
            ..LocaliserConfig::new(black_box(CAMERA), WIDTH as u32, HEIGHT as u32)
        };
        let Ok(loc) = slot.write(Localiser::new(&config)) else { halt() };
        let Ok(mut sem) = Network::new(black_box(MODEL_BLOB), WIDTH, HEIGHT, storage.memory())
        else {
            halt()
        };
        let (left, right) = buf.split_at(PIXELS);
        let mut t = 0.0;
        loop {
            let out = loc.process_raw(black_box(left), black_box(right), t, Some(&mut sem));
            black_box(out.ok());
            t += 0.1;
        }
    }

    #[panic_handler]
    fn panic(_: &core::panic::PanicInfo<'_>) -> ! {
        halt()
    }
}
