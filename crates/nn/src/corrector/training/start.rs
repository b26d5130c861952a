//! The models training starts from and distils, checked against the configuration.

use std::path::Path;

use burn::module::Module;
use burn::tensor::Device;

use super::config::TrainingConfig;
use crate::corrector::inference::{load_net, CONFIG_FILE};
use crate::corrector::model::CorrectorNet;
use crate::corrector::normalise::Normalisation;
use crate::error::{Error, Result};
use crate::sim::coarse::crease_label;

/// The network, statistics and configuration of the trained corrector `cfg` starts from
/// ([`TrainingConfig::init_from`]), checked against `cfg`; `None` without one.
pub(super) fn warm_start(
    cfg: &TrainingConfig,
    device: &Device,
) -> Result<Option<(CorrectorNet, Normalisation)>> {
    let Some(dir) = cfg.init_from.as_deref() else {
        return Ok(None);
    };
    let (net, norm, old) = load_net(dir, device)?;
    let config_path = dir.join(CONFIG_FILE);
    let (a, b) = (&old.model, &cfg.model);
    if (
        a.latent,
        a.hidden_layers,
        a.steps,
        a.attention,
        a.decoder_kind(),
    ) != (
        b.latent,
        b.hidden_layers,
        b.steps,
        b.attention,
        b.decoder_kind(),
    ) {
        return Err(Error::bad_input(
            &config_path,
            format!(
                "the network to start from has latent {}, {} hidden layers, {} blocks, \
                 attention {}, decoder {:?}; the training asks for {}, {}, {}, {}, {:?}",
                a.latent,
                a.hidden_layers,
                a.steps,
                a.attention,
                a.decoder_kind(),
                b.latent,
                b.hidden_layers,
                b.steps,
                b.attention,
                b.decoder_kind()
            ),
        ));
    }
    check_same_coarse(&old, cfg, &config_path, "the network to start from")?;
    Ok(Some((net, norm)))
}

/// Refuses (naming `config_path`) a trained corrector (`what`, configured as `old`) trained
/// beside another coarse model than `cfg` asks for.
pub(super) fn check_same_coarse(
    old: &TrainingConfig,
    cfg: &TrainingConfig,
    config_path: &Path,
    what: &str,
) -> Result<()> {
    if old.coarse_friction != cfg.coarse_friction {
        return Err(Error::bad_input(
            config_path,
            format!(
                "{what} was trained beside a coarse friction coefficient \
                 of {:?}, the training asks for {:?} (None: the simulator's)",
                old.coarse_friction, cfg.coarse_friction
            ),
        ));
    }
    let (old_b, new_b) = (
        old.coarse_bending.unwrap_or(1.0),
        cfg.coarse_bending.unwrap_or(1.0),
    );
    if old_b != new_b {
        return Err(Error::bad_input(
            config_path,
            format!(
                "{what} was trained beside {old_b} times the fabric's \
                 bending stiffness, the training asks for {new_b}"
            ),
        ));
    }
    let (old_e, new_e) = (
        crease_label(old.coarse_crease_contacts),
        crease_label(cfg.coarse_crease_contacts),
    );
    if old_e != new_e {
        return Err(Error::bad_input(
            config_path,
            format!(
                "{what} was trained with crease contacts {old_e}, the \
                 training asks for {new_e}"
            ),
        ));
    }
    if old.coarse_wrinkle_bending != cfg.coarse_wrinkle_bending {
        return Err(Error::bad_input(
            config_path,
            format!(
                "{what} was trained beside a coarse wrinkle bending gain \
                 of {:?}, the training asks for {:?} (None: off)",
                old.coarse_wrinkle_bending, cfg.coarse_wrinkle_bending
            ),
        ));
    }
    if old.compression_factor() != cfg.compression_factor()
        || old.coarse_compression_knee != cfg.coarse_compression_knee
    {
        return Err(Error::bad_input(
            config_path,
            format!(
                "{what} was trained beside a coarse membrane with \
                 compression factor {} (knee {:?}), the training asks for {} (knee {:?})",
                old.compression_factor(),
                old.coarse_compression_knee,
                cfg.compression_factor(),
                cfg.coarse_compression_knee
            ),
        ));
    }
    Ok(())
}

/// The teacher network `cfg` distils ([`TrainingConfig::distil_from`]), without gradients,
/// and its statistics; `None` without one.
pub(super) fn teacher(
    cfg: &TrainingConfig,
    device: &Device,
) -> Result<Option<(CorrectorNet, Normalisation)>> {
    let Some(dir) = cfg.distil_from.as_deref() else {
        return Ok(None);
    };
    let (net, norm, old) = load_net(dir, device)?;
    check_same_coarse(&old, cfg, &dir.join(CONFIG_FILE), "the teacher")?;
    Ok(Some((net.no_grad(), norm)))
}
