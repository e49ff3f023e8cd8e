//! The memory budget: a grid or a field basis that would not fit is refused before it is
//! allocated, with a message that says how to make it smaller.

use crate::error::{HasError, Result};

/// Budget when the machine's free memory cannot be read (bytes).
const FALLBACK: u64 = 8 << 30;
/// Share of the available memory one request may plan to use.
const SHARE: f64 = 0.8;

/// Bytes one request may use: `ARFI_MEMORY_LIMIT_GIB` if set, else 80 % of the memory the
/// kernel reports available (`MemAvailable` in `/proc/meminfo`), else 8 GiB.
pub fn limit() -> u64 {
    if let Some(gib) = std::env::var("ARFI_MEMORY_LIMIT_GIB").ok().and_then(|s| s.trim().parse::<f64>().ok()) {
        if gib.is_finite() && gib > 0.0 {
            return (gib * (1u64 << 30) as f64) as u64;
        }
    }
    available().map_or(FALLBACK, |b| (b as f64 * SHARE) as u64)
}

/// `MemAvailable` from `/proc/meminfo` (bytes), where there is one.
fn available() -> Option<u64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024)
}

/// Refuses `what` if it needs more than [`limit`] bytes; `suggestion` says how to shrink it.
pub fn check(what: impl FnOnce() -> String, bytes: u64, suggestion: &str) -> Result<()> {
    let limit = limit();
    if bytes > limit {
        return Err(HasError::TooLarge { what: what(), bytes, limit, suggestion: suggestion.to_string() });
    }
    Ok(())
}

/// Hands the memory the allocator holds free back to the system (glibc's `malloc_trim`; nothing
/// elsewhere). Call after dropping a HAS plan: glibc keeps freed plane-sized buffers in its heap,
/// and a plan built next beside them does not reuse them all, so that two plans built one after
/// the other cost the process the memory of both (a 650 kHz head's prediction would hold 3 GB of
/// its first plan's 4 GB through the second's build).
pub fn release_freed() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: malloc_trim only returns free heap pages to the system; it takes no pointer.
    unsafe {
        libc::malloc_trim(0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_budget_is_positive_and_a_request_beyond_it_is_refused_with_the_suggestion() {
        let l = limit();
        assert!(l > 0);
        assert!(check(|| "x".into(), l, "").is_ok());
        let e = check(|| "a huge grid".into(), l.saturating_mul(2).max(l + 1), "use a coarser grid").unwrap_err();
        let text = e.to_string();
        assert!(text.starts_with("a huge grid needs") && text.ends_with("use a coarser grid"), "{text}");
    }
}
