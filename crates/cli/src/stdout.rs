//! The commands' reports on stdout, and their notes on stderr. `println!` and `eprintln!`
//! panic when the reader has gone (`lidar-har bag info BAG | head -2`, `lidar-har dataset
//! ... 2>&1 | head`); here the text stops instead, and the command goes on to finish the
//! files it writes.

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
            note(format_args!(
                "lidar-har: warning: the report on stdout stops here: {e}\n"
            ));
        }
    }
}

/// Writes a note to stderr; nothing when stderr cannot be written to.
pub fn note(args: std::fmt::Arguments) {
    // Nowhere left to say that the notes stopped: the files and exit status still say it all.
    let _ = std::io::stderr().lock().write_fmt(args);
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

/// `eprintln!` for notes, without the panic on a closed stderr.
macro_rules! errln {
    ($($arg:tt)*) => {
        $crate::stdout::note(format_args!("{}\n", format_args!($($arg)*)))
    };
}
