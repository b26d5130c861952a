//! The model a warm start begins from, checked against the configuration.

use std::path::Path;

use burn::tensor::Device;

use super::config::TrainingConfig;
use crate::corrector::inference::{load_net, CONFIG_FILE};
use crate::corrector::model::CorrectorNet;
use crate::corrector::normalise::Normalisation;
use clothsr_geometry::error::{Error, Result};
use clothsr_sim::coarse::{crease_label, CoarseCalibration};

/// The network and statistics of the trained corrector `cfg` starts from
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
    if (a.latent, a.hidden_layers, a.steps, a.attention, a.decoder)
        != (b.latent, b.hidden_layers, b.steps, b.attention, b.decoder)
    {
        return Err(Error::bad_input(
            &config_path,
            format!(
                "the network to start from has latent {}, {} hidden layers, {} blocks, \
                 attention {}, decoder {:?}; the training asks for {}, {}, {}, {}, {:?}",
                a.latent,
                a.hidden_layers,
                a.steps,
                a.attention,
                a.decoder,
                b.latent,
                b.hidden_layers,
                b.steps,
                b.attention,
                b.decoder
            ),
        ));
    }
    check_same_coarse(&old.coarse, &cfg.coarse, &config_path)?;
    Ok(Some((net, norm)))
}

/// Refuses (naming `config_path`) a network to start from that was trained beside another
/// coarse model (`old`) than the training asks for (`new`).
fn check_same_coarse(
    old: &CoarseCalibration,
    new: &CoarseCalibration,
    config_path: &Path,
) -> Result<()> {
    let refuse = |how: String| {
        Err(Error::bad_input(
            config_path,
            format!("the network to start from was trained {how}"),
        ))
    };
    if old.friction != new.friction {
        return refuse(format!(
            "beside a coarse friction coefficient of {:?}, the training asks for {:?} \
             (None: the simulator's)",
            old.friction, new.friction
        ));
    }
    let (old_b, new_b) = (old.bending.unwrap_or(1.0), new.bending.unwrap_or(1.0));
    if old_b != new_b {
        return refuse(format!(
            "beside {old_b} times the fabric's bending stiffness, the training asks for {new_b}"
        ));
    }
    let (old_e, new_e) = (
        crease_label(old.crease_contacts),
        crease_label(new.crease_contacts),
    );
    if old_e != new_e {
        return refuse(format!(
            "with crease contacts {old_e}, the training asks for {new_e}"
        ));
    }
    if old.wrinkle_bending != new.wrinkle_bending {
        return refuse(format!(
            "beside a coarse wrinkle bending gain of {:?}, the training asks for {:?} \
             (None: off)",
            old.wrinkle_bending, new.wrinkle_bending
        ));
    }
    let (old_c, new_c) = (
        old.compression.unwrap_or(1.0),
        new.compression.unwrap_or(1.0),
    );
    if old_c != new_c || old.compression_knee != new.compression_knee {
        return refuse(format!(
            "beside a coarse membrane with compression factor {old_c} (knee {:?}), the \
             training asks for {new_c} (knee {:?})",
            old.compression_knee, new.compression_knee
        ));
    }
    Ok(())
}
