"""`no_image`: no image, for trackers that work from events alone (Tracker.reads_images False)."""

from __future__ import annotations

from eas_vo.plugins import Frontend


class NoImageFrontend(Frontend):
    """Makes no image: the pipeline never calls it, and the tracker gets `image=None`. A run
    whose tracker reads no images uses it whatever run.frontend says."""

    name = "no_image"
    description = "no image (chosen by itself for trackers that read only events, e.g. cmax)"
    makes_images = False
