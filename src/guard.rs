//! A guard around third-party code that may panic on hostile input (usvg's geometry on
//! sizes near `f32::MAX`, tiny-skia's rasterizer on far coordinates): the panic becomes a
//! message for the usual one-line error, and nothing is printed.

thread_local! {
    /// Set while this thread runs third-party code under [`quietly`]: its panic message is dropped.
    static QUIET: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Runs `f`, catching a panic and returning its message instead. While `f` runs, the panic
/// hook (installed once, passing every other panic to the previous hook) prints nothing
/// for this thread, so a caught panic costs no stray lines on stderr.
pub(crate) fn quietly<R>(f: impl FnOnce() -> R) -> std::result::Result<R, String> {
    static HOOK: std::sync::Once = std::sync::Once::new();
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !QUIET.with(|q| q.get()) {
                previous(info);
            }
        }));
    });
    let was = QUIET.with(|q| q.replace(true));
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    QUIET.with(|q| q.set(was));
    r.map_err(|payload| {
        payload
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| payload.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "no message".to_string())
    })
}

#[cfg(test)]
mod tests {
    use super::{QUIET, quietly};

    #[test]
    fn a_value_passes_and_a_panic_becomes_its_message() {
        assert_eq!(quietly(|| 7), Ok(7));
        let r: Result<(), String> = quietly(|| panic!("far too {}", "big"));
        assert_eq!(r, Err("far too big".to_string()));
        let r: Result<u8, String> = quietly(|| std::hint::black_box(None::<u8>).unwrap());
        assert!(r.unwrap_err().contains("None"));
        // The hook is back to normal for everything else.
        assert!(!QUIET.with(|q| q.get()));
    }
}
