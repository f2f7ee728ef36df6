"""The scene simulator and the chain path together: settings (:mod:`.config`), the
scene's draws and raw cubes (:mod:`.scene`), campaigns (:mod:`.campaign`), and the
augmentation renderer's chain path (:mod:`.path`, reduced by :mod:`.plan`,
:mod:`.target` and :mod:`.image`)."""
from .campaign import (PER_CLASS, PER_ROW, Campaign, as_profile_set, load_campaign, save_campaigns,
                       simulate_campaign)
from .config import SCENE_PHASES, SceneConfig
from .path import METHODS, SEARCH_BINS, ChainProfiles, render_through_chain
from .scene import CHUNK_ACQ, Draws, draw_acquisitions, draw_specimens, literal_chain, render_cubes, true_vectors

__all__ = [
    "PER_CLASS", "PER_ROW", "Campaign", "as_profile_set", "load_campaign", "save_campaigns", "simulate_campaign",
    "SCENE_PHASES", "SceneConfig", "METHODS", "SEARCH_BINS", "ChainProfiles", "render_through_chain", "CHUNK_ACQ",
    "Draws", "draw_acquisitions", "draw_specimens", "literal_chain", "render_cubes", "true_vectors",
]
