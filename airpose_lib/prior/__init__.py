"""Pose prior: a VPoser-v2-architecture VAE (the official V02_05 weights load into it), its
training on the kit's pose corpus, and loading of kit / official checkpoints."""

from .checkpoint import (
    KIT_TAGS,
    VPOSER_ENV,
    VPOSER_URL,
    PriorError,
    find_vposer_checkpoint,
    kit_prior_path,
    load_prior,
    save_prior,
    vposer_state_dict,
)
from .train import CorpusConfig, PriorTrainConfig, evaluate_prior, rotation_geodesic, train_prior
from .vposer import LATENT_DIM, NUM_JOINTS, NUM_NEURONS, VPoser

__all__ = [
    "VPoser", "LATENT_DIM", "NUM_JOINTS", "NUM_NEURONS",
    "PriorTrainConfig", "CorpusConfig", "train_prior", "evaluate_prior", "rotation_geodesic",
    "PriorError", "VPOSER_ENV", "VPOSER_URL", "KIT_TAGS", "kit_prior_path", "save_prior",
    "load_prior", "find_vposer_checkpoint", "vposer_state_dict",
]
