//! The AFF (BART) parser on in-memory files: the input is split at NUL bytes into files;
//! the first is `main.aff`, each later one is named by its first line (so includes and PPM
//! textures resolve among them). Any input must load or give an error, never panic.
#![no_main]

use std::path::PathBuf;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let mut chunks = data.split(|&b| b == 0);
    let main = chunks.next().unwrap_or_default().to_vec();
    let mut files = vec![(PathBuf::from("main.aff"), main)];
    for chunk in chunks {
        let (name, contents) = match chunk.iter().position(|&b| b == b'\n') {
            Some(i) => (&chunk[..i], &chunk[i + 1..]),
            None => (chunk, &[][..]),
        };
        let name = String::from_utf8_lossy(name).trim().to_string();
        files.push((PathBuf::from(name), contents.to_vec()));
    }
    let _ = mipray::scene::aff::load_from_memory(&PathBuf::from("main.aff"), files);
});
