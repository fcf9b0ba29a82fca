//! OctoMap `.ot` / `.bt` readers on arbitrary bytes: never panic; a map they accept writes back
//! (in its own format) to a file that reads back to the same node count, and a `.ot` body that
//! parses writes back to the same bytes when the input was written by us.
#![no_main]

use libfuzzer_sys::fuzz_target;
use rovlink_octo::files::{self, MapFormat};

fuzz_target!(|data: &[u8]| {
    let Ok(tree) = files::read_map(data) else {
        return;
    };
    let Ok(header) = files::read_header(data) else {
        panic!("a map that reads has a header");
    };
    let again = match header.format {
        MapFormat::Ot => files::write_ot(&tree),
        MapFormat::Bt => files::write_bt(&tree),
    };
    let back = files::read_map(&again).expect("what we write reads back");
    if header.format == MapFormat::Ot {
        assert_eq!(back.num_nodes(), tree.num_nodes());
        assert_eq!(files::write_ot(&back), again);
    }
});
