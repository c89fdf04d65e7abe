//! The settings loader under proptest: whatever the EEPROM holds, loading
//! never panics, and it yields either a refusal or exactly an image that was
//! saved — never a mix of saved and random bytes.

use firmware::settings::Settings;
use firmware::storage::{self, MemoryStorage, SLOT_LEN};
use proptest::prelude::*;

type Eeprom = MemoryStorage<4096>;

fn config() -> ProptestConfig {
    // Bounded for the test command; raise PROPTEST_CASES for a long run.
    ProptestConfig { cases: 512, ..ProptestConfig::default() }
}

fn saved(e_steps: i32) -> Settings {
    let mut settings = Settings::default();
    settings.steps_per_mm_milli[3] = e_steps;
    settings
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn random_eeprom_contents_never_load_half_way(bytes in proptest::collection::vec(any::<u8>(), 2 * SLOT_LEN)) {
        let mut eeprom = Eeprom::new();
        eeprom.bytes[..bytes.len()].copy_from_slice(&bytes);
        // Random bytes pass a 16-bit CRC and the magic about never; if they
        // did, the loader must still hand back a whole image.
        if let Ok((settings, stored)) = storage::load(&mut eeprom) {
            prop_assert_eq!(stored.bytes, SLOT_LEN);
            let _ = settings;
        }
    }

    #[test]
    fn a_damaged_image_loads_the_older_one_or_nothing(
        flips in proptest::collection::vec((0usize..2 * SLOT_LEN, 0u8..8), 1..6),
    ) {
        let mut eeprom = Eeprom::new();
        storage::save(&mut eeprom, &saved(415_000)).unwrap();
        storage::save(&mut eeprom, &saved(500_000)).unwrap();
        for (at, bit) in flips {
            eeprom.bytes[at] ^= 1 << bit;
        }
        if let Ok((settings, _)) = storage::load(&mut eeprom) {
            prop_assert!(settings == saved(415_000) || settings == saved(500_000));
        }
    }
}
