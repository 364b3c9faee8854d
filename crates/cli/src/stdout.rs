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
    if let Err(e) = std::io::stdout().lock().write_fmt(args) {
        READER_GONE.store(true, Ordering::Relaxed);
        // A reader leaving is normal; a full disk or a broken device is worth a word.
        if e.kind() != std::io::ErrorKind::BrokenPipe {
            eprintln!("lidar-har: warning: the report on stdout stops here: {e}");
        }
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
