//! The commands' reports on stdout. `println!` panics when the reader has gone
//! (`lidar-har bag info BAG | head -2`); here the report stops instead, and the command goes
//! on to finish the files it writes.

use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};

/// Set at the first failed write: the rest of the report has nowhere to go.
static READER_GONE: AtomicBool = AtomicBool::new(false);

pub fn write(args: std::fmt::Arguments) {
    if READER_GONE.load(Ordering::Relaxed) {
        return;
    }
    if std::io::stdout().lock().write_fmt(args).is_err() {
        READER_GONE.store(true, Ordering::Relaxed);
    }
}

/// `print!` for reports, without the panic on a closed stdout.
macro_rules! out {
    ($($arg:tt)*) => {
        $crate::stdout::write(format_args!($($arg)*))
    };
}

/// `println!` for reports, without the panic on a closed stdout.
macro_rules! outln {
    () => {
        $crate::stdout::write(format_args!("\n"))
    };
    ($($arg:tt)*) => {
        $crate::stdout::write(format_args!("{}\n", format_args!($($arg)*)))
    };
}
