//! The EvoLogics AT dialect readers, from any bytes in any chunking: `CommandReader` (what
//! link-sim hears from a host) and `NotificationReader` (what modem-bench hears from a modem).
//!
//! Byte 0 is the chunk length (1..=64). Checks: neither reader panics; every command and
//! notification read re-formats to bytes that read back to the same item (except an `Other`
//! line that starts like a data item: read alone, the reader rightly waits for its data);
//! reading in chunks gives the same items as reading everything at once.

#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink_link::gll::evologics::{
    Command, CommandReader, Notification, NotificationReader, format_command, format_notification,
};

/// True for an `Other` line that begins like an item with binary data.
fn looks_like_data(line: &str) -> bool {
    ["AT*SEND,", "AT*SENDIM,", "RECV,", "RECVIM,"]
        .iter()
        .any(|prefix| line.starts_with(prefix))
}

fuzz_target!(|data: &[u8]| {
    let Some((&first, stream)) = data.split_first() else {
        return;
    };
    let chunk = usize::from(first % 64) + 1;

    let mut whole = CommandReader::new();
    whole.push(stream);
    let all: Vec<_> = std::iter::from_fn(|| whole.next_command()).collect();
    let mut chunked = CommandReader::new();
    let mut pieces = Vec::new();
    for part in stream.chunks(chunk) {
        chunked.push(part);
        pieces.extend(std::iter::from_fn(|| chunked.next_command()));
    }
    if stream.len() <= 1024 {
        // Past a maximal item the readers drop garbage, which depends on the chunking.
        assert_eq!(all, pieces, "commands depend on the chunking");
    }
    for command in &all {
        if matches!(command, Command::Other(line) if looks_like_data(line)) {
            continue;
        }
        let mut again = CommandReader::new();
        again.push(&format_command(command));
        assert_eq!(again.next_command().as_ref(), Some(command), "command does not round trip");
    }

    let mut whole = NotificationReader::new();
    whole.push(stream);
    let all: Vec<_> = std::iter::from_fn(|| whole.next_notification()).collect();
    let mut chunked = NotificationReader::new();
    let mut pieces = Vec::new();
    for part in stream.chunks(chunk) {
        chunked.push(part);
        pieces.extend(std::iter::from_fn(|| chunked.next_notification()));
    }
    if stream.len() <= 1024 {
        assert_eq!(all, pieces, "notifications depend on the chunking");
    }
    for note in &all {
        if matches!(note, Notification::Other(line) if looks_like_data(line)) {
            continue;
        }
        let mut again = NotificationReader::new();
        again.push(&format_notification(note));
        let back = again.next_notification();
        // Velocities are printed with two decimals: compare the re-formatted bytes instead.
        let reformatted = back.as_ref().map(format_notification);
        assert_eq!(reformatted, Some(format_notification(note)), "notification does not round trip");
    }
});
