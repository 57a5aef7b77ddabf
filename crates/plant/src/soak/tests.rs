use super::*;

fn short(cycles: u64) -> SoakConfig {
    SoakConfig {
        cycles,
        max_rss_growth: None,
        ..SoakConfig::default()
    }
}

#[test]
fn every_profile_has_a_slave_and_reaches_data_exchange() {
    let slaves = plant::stations(&SoakConfig::default()).unwrap().slaves;
    let names: Vec<&str> = slaves.iter().map(|(s, _)| plant::profile(s)).collect();
    for p in profibus_devices::PROFILES {
        assert!(names.contains(&p.name), "{} missing", p.name);
    }
    // A clean line: no disturbance at all.
    let cfg = SoakConfig {
        drop: 0.0,
        flip_ber: 0.0,
        noise_rate: 0.0,
        ..short(300)
    };
    let r = run(&cfg, |_| {}).unwrap();
    assert!(r.passed(), "{:?}", r.violations);
    assert_eq!(r.cycles, 300);
    assert_eq!(r.disturbances, 0);
    assert_eq!(r.integrity.corrupted, 0, "{:?}", r.integrity);
    assert_eq!(r.integrity.undetected, 0);
    for s in &r.slaves {
        assert!(s.data_exchanges >= 250, "{s:?}");
    }
}

#[test]
fn a_short_soak_sees_faults_and_recovers() {
    let r = run(&short(2000), |_| {}).unwrap();
    assert!(r.passed(), "{:?}", r.violations);
    assert!(r.medium.dropped > 0 && r.medium.bits_flipped > 0 && r.medium.noise_bursts > 0);
    assert!(r.integrity.corrupted > 0 && r.receiver_errors > 0, "{r:?}");
    assert!(r.disturbances > 0 && r.recovery.count() == r.disturbances);
    // The same seed gives the same run.
    let again = run(&short(2000), |_| {}).unwrap();
    assert_eq!((again.medium, again.integrity), (r.medium, r.integrity));
}

#[test]
fn an_unplugged_slave_breaks_the_recovery_invariant() {
    let cfg = SoakConfig {
        unplug: Some((5, 200)),
        ..short(3000)
    };
    let r = run(&cfg, |_| {}).unwrap();
    match &r.violations[..] {
        [Violation::NotRecovered { address: 5, .. }] => {}
        v => panic!("{v:?}"),
    }
    let text = r.violations[0].to_string();
    assert!(
        text.contains("slave 5 (omega)") && text.contains("Data_Exchange"),
        "{text}"
    );
}

#[test]
fn forged_tokens_are_counted_and_every_invariant_holds() {
    // Bit errors ten times as often as in the default soak: SD4 tokens
    // (no FCS) get forged, the only master sees some of them as a second
    // token, drops its own and claims it again; nothing else breaks.
    let cfg = SoakConfig {
        flip_ber: 1e-3,
        ..short(1000)
    };
    let r = run(&cfg, |_| {}).unwrap();
    eprintln!("{r}");
    assert!(r.passed(), "{:?}", r.violations);
    let (i, t) = (&r.integrity, &r.token_ring);
    assert!(
        i.forged_tokens > 0 && i.forged_tokens <= i.undetected,
        "{i:?}"
    );
    assert!(i.noise_tokens <= i.noise_telegrams, "{i:?}");
    assert!(t.duplicate_tokens > 0, "{t:?}");
    // Each dropped token is claimed again (plus the first claim).
    assert!(t.claims > t.duplicate_tokens, "{t:?}");
    let text = r.to_string();
    assert!(
        text.contains(&format!(
            "dropped its token {} times for a duplicate token",
            t.duplicate_tokens
        )),
        "{text}"
    );
}

#[test]
fn a_profile_error_is_named_once() {
    let e = profibus_devices::profile::read_option_file(std::path::Path::new(
        "/nonexistent/params.toml",
    ))
    .unwrap_err();
    // The cause is in the message and not also the source, so that a
    // printed chain (`dpctl: {e:#}`) names it once.
    let e = SoakError::Profile {
        name: "omega",
        error: e,
    };
    assert!(std::error::Error::source(&e).is_none());
}
