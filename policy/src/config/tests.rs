//! Config parsing, presets and what a bad one is told.

use super::*;

#[test]
fn a_sin_cos_pos_embed_parses_and_is_refused_where_it_cannot_be() {
    for s in ["sin-cos", "sincos", "SIN_COS"] {
        assert_eq!(s.parse::<PosEmbed>().ok(), Some(PosEmbed::SinCos), "{s}");
    }
    assert_eq!("learned".parse::<PosEmbed>().ok(), Some(PosEmbed::Learned));
    assert_eq!(
        "learned-sin-cos".parse::<PosEmbed>().ok(),
        Some(PosEmbed::LearnedSinCos)
    );
    assert_eq!(PosEmbed::LearnedSinCos.to_string(), "learned-sin-cos");
    assert!("rope".parse::<PosEmbed>().is_err());
    let mut c = ModelConfig::new(ModelSize::Ti, vec![], (64, 64), 3, 2);
    c.pos_embed = PosEmbed::SinCos;
    assert!(c.validate().is_ok());
    c.hidden = 36;
    c.heads = 3;
    assert!(c.validate().is_ok(), "36 is even");
    (c.hidden, c.heads) = (33, 3);
    let e = c
        .validate()
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(e.contains("even width"), "{e}");
    let mut d = ModelConfig::dp_t(vec![], (64, 64), 3, 2);
    d.pos_embed = PosEmbed::SinCos;
    let e = d
        .validate()
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(e.contains("DP-T"), "{e}");
    // Configs written before the field read as the learned embedding.
    let mut v = serde_json::to_value(ModelConfig::new(ModelSize::Ti, vec![], (8, 8), 3, 2))
        .unwrap_or_default();
    if let Some(o) = v.as_object_mut() {
        o.remove("pos_embed");
    }
    let old: Option<ModelConfig> = serde_json::from_value(v).ok();
    assert_eq!(old.map(|c| c.pos_embed), Some(PosEmbed::Learned));
}
