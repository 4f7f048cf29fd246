//! AnimateAnyMesh's side of the correspondence (docs/method.md §12): the rules that rename any4d's parameter paths to
//! its `state_dict` keys, the keys it has that no any4d parameter stands for, and its VAE's constant buffers.

use super::Network;

/// The renaming rules from any4d's paths (after PyTorch's layout is applied: LayerNorm `weight`/`bias`) to
/// AnimateAnyMesh's keys, applied in order, each to the result of the one before (docs/method.md §12).
pub fn aam_rules(network: Network) -> &'static [(&'static str, &'static str)] {
    match network {
        Network::Mmdit => MMDIT_RULES,
        Network::FrameVae => FRAME_VAE_RULES,
        Network::DyMeshVae => DYMESH_VAE_RULES,
    }
}

const MMDIT_RULES: &[(&str, &str)] = &[
    (r"^input_norm\.", "ln_pre."),
    (r"^text_proj\.", "clip_token_mlp."),
    (r"^text_norm\.", "ln_pre_text."),
    (r"^time\.fc1\.", "time_embed.c_fc."),
    (r"^time\.fc2\.", "time_embed.c_proj."),
    (
        r"^blocks\.(\d+)\.ada_motion\.",
        "backbone.resblocks.${1}.adaln_x.linear.",
    ),
    (
        r"^blocks\.(\d+)\.ada_text\.",
        "backbone.resblocks.${1}.adaln_text.linear.",
    ),
    (r"^blocks\.(\d+)\.qkv\.", "backbone.resblocks.${1}.attn.c_qkv."),
    (r"^blocks\.(\d+)\.proj\.", "backbone.resblocks.${1}.attn.c_proj."),
    (r"^blocks\.(\d+)\.norm2_motion\.", "backbone.resblocks.${1}.ln_x."),
    (r"^blocks\.(\d+)\.norm2_text\.", "backbone.resblocks.${1}.ln_text."),
    (r"^blocks\.(\d+)\.fc1\.", "backbone.resblocks.${1}.mlp.c_fc."),
    (r"^blocks\.(\d+)\.fc2\.", "backbone.resblocks.${1}.mlp.c_proj."),
    (r"^final_norm\.", "ln_post."),
];

/// The VAE body's rules, shared by both VAEs: a Sync block's attention half is AAM's `.0.`, its FFN half `.1.`.
macro_rules! vae_body_rules {
    ($($extra:expr),* $(,)?) => {
        &[
            $($extra,)*
            (r"^body\.point_embed\.linear\.", "point_embed.mlp."),
            (r"^body\.neighbour\.(norm_q|norm_k|norm_v)\.", "neighbor_layers.0.${1}."),
            (r"^body\.neighbour\.(to_q|to_k|to_v|to_out)\.", "neighbor_layers.0.fn.${1}."),
            (r"^body\.(encoder|decoder)\.(\d+)\.norm_q\.", "body.${1}.${2}.0.norm_q."),
            (r"^body\.(encoder|decoder)\.(\d+)\.norm_k\.", "body.${1}.${2}.0.norm_k."),
            (r"^body\.(encoder|decoder)\.(\d+)\.norm_v_shape\.", "body.${1}.${2}.0.norm_v1."),
            (r"^body\.(encoder|decoder)\.(\d+)\.norm_v_motion\.", "body.${1}.${2}.0.norm_v2."),
            (r"^body\.(encoder|decoder)\.(\d+)\.attn\.to_q\.", "body.${1}.${2}.0.attn.to_q."),
            (r"^body\.(encoder|decoder)\.(\d+)\.attn\.to_k\.", "body.${1}.${2}.0.attn.to_k."),
            (r"^body\.(encoder|decoder)\.(\d+)\.attn\.to_v\.0\.", "body.${1}.${2}.0.attn.to_v1."),
            (r"^body\.(encoder|decoder)\.(\d+)\.attn\.to_v\.1\.", "body.${1}.${2}.0.attn.to_v2."),
            (r"^body\.(encoder|decoder)\.(\d+)\.attn\.to_out\.0\.", "body.${1}.${2}.0.attn.to_out1."),
            (r"^body\.(encoder|decoder)\.(\d+)\.attn\.to_out\.1\.", "body.${1}.${2}.0.attn.to_out2."),
            (r"^body\.(encoder|decoder)\.(\d+)\.norm_ff_shape\.", "body.${1}.${2}.1.norm1."),
            (r"^body\.(encoder|decoder)\.(\d+)\.norm_ff_motion\.", "body.${1}.${2}.1.norm2."),
            (r"^body\.(encoder|decoder)\.(\d+)\.ff_shape\.proj_in\.", "body.${1}.${2}.1.ffn.ffn1.0."),
            (r"^body\.(encoder|decoder)\.(\d+)\.ff_shape\.proj_out\.", "body.${1}.${2}.1.ffn.ffn1.2."),
            (r"^body\.(encoder|decoder)\.(\d+)\.ff_motion\.proj_in\.", "body.${1}.${2}.1.ffn.ffn2.0."),
            (r"^body\.(encoder|decoder)\.(\d+)\.ff_motion\.proj_out\.", "body.${1}.${2}.1.ffn.ffn2.2."),
            (r"^body\.z0_head\.", "mean_fc_x0."),
            (r"^body\.mu_head\.", "mean_fc_xt."),
            (r"^body\.logvar_head\.", "logvar_fc_xt."),
            (r"^body\.z0_in\.", "proj_x0."),
            (r"^body\.z_in\.", "proj_xt."),
            (r"^body\.query_proj\.", "fc_query."),
            (r"^body\.query_norm\.", "decoder_final_ca.norm_q."),
            (r"^body\.token_norm_k\.", "decoder_final_ca.norm_k."),
            (r"^body\.token_norm_v\.", "decoder_final_ca.norm_v."),
            (r"^body\.query_attn\.(to_q|to_k)\.", "decoder_final_ca.fn.${1}."),
            (r"^body\.query_attn\.to_v\.0\.", "decoder_final_ca.fn.to_v."),
            (r"^body\.query_attn\.to_out\.0\.", "decoder_final_ca.fn.to_out."),
            (r"^body\.to_offsets\.", "to_outputs."),
            (r"^body\.encoder\.", "enc_blocks."),
            (r"^body\.decoder\.", "dec_blocks."),
        ]
    };
}

const FRAME_VAE_RULES: &[(&str, &str)] = vae_body_rules!((r"^offset_embed\.linear\.", "traj_embed.mlp."));
const DYMESH_VAE_RULES: &[(&str, &str)] = vae_body_rules!((r"^traj_embed\.linear\.", "traj_embed.mlp."));

/// Keys of an AnimateAnyMesh `state_dict` that no any4d parameter stands for: the VAEs' constant buffers and the
/// MMDiT's CLIP text tower. Reading ignores them; everything else must match.
pub(super) fn aam_extra(network: Network, key: &str) -> bool {
    match network {
        Network::Mmdit => key.starts_with("clip_text_model."),
        Network::FrameVae | Network::DyMeshVae => key == "point_embed.basis" || key == "traj_embed.freq_bands",
    }
}

/// AnimateAnyMesh's two VAE buffers: `point_embed.basis` `[3, 3·point_freqs]` (row `i` holds `2^k·π`,
/// k = 0..point_freqs, in its own block of columns) and `traj_embed.freq_bands` `[offset_freqs, 1]` (`2^k`), as
/// its `PointEmbed` and `TrajEncoding` register them.
pub fn aam_vae_buffers(point_freqs: usize, offset_freqs: usize) -> Vec<(String, Vec<usize>, Vec<f32>)> {
    let k = point_freqs;
    let mut basis = vec![0f32; 3 * 3 * k];
    for row in 0..3 {
        for j in 0..k {
            basis[row * 3 * k + row * k + j] = 2f32.powi(j as i32) * std::f32::consts::PI;
        }
    }
    let bands = (0..offset_freqs).map(|j| 2f32.powi(j as i32)).collect();
    vec![
        ("point_embed.basis".into(), vec![3, 3 * k], basis),
        ("traj_embed.freq_bands".into(), vec![offset_freqs, 1], bands),
    ]
}
