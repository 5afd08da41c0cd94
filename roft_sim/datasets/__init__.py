"""Datasets on disk (fast-ycb, bop, hdf5) behind one lazy ``Sequence`` reader interface.

Writing: :func:`open_writer` gives a streaming :class:`SequenceWriter` that takes one
:class:`DatasetFrame` per camera frame (atomic per frame, any order, resumable, picklable for
worker processes). Reading: :func:`open_sequence` detects the format and returns a lazy
:class:`Sequence`; :func:`list_sequences` finds the sequences of a dataset root. The formats are
specified in docs/formats.md; :func:`check_fast_ycb_sequence` is an independent format checker.
"""

from roft_sim.datasets.base import GT_MASK_SET, DetectorPoses, InMemorySequence, Sequence
from roft_sim.datasets.bop import BopSequence
from roft_sim.datasets.fast_ycb import FastYcbSequence
from roft_sim.datasets.fast_ycb_check import FastYcbCheckReport, check_fast_ycb_sequence
from roft_sim.datasets.formats import (
    DATASET_FORMATS,
    DatasetFormat,
    dataset_frames,
    detect_format,
    find_sequences,
    list_sequences,
    open_sequence,
    open_writer,
    write_sequence,
)
from roft_sim.datasets.frames import (
    FLOW_ENCODINGS,
    GT_FULL_MASK_SET,
    DatasetFrame,
    FlowEncoding,
    SequenceWriter,
)
from roft_sim.datasets.hdf5 import Hdf5Sequence

__all__ = [
    "GT_MASK_SET",
    "GT_FULL_MASK_SET",
    "DetectorPoses",
    "InMemorySequence",
    "Sequence",
    "DatasetFrame",
    "SequenceWriter",
    "FlowEncoding",
    "FLOW_ENCODINGS",
    "DatasetFormat",
    "DATASET_FORMATS",
    "open_writer",
    "open_sequence",
    "detect_format",
    "list_sequences",
    "find_sequences",
    "dataset_frames",
    "write_sequence",
    "FastYcbSequence",
    "BopSequence",
    "Hdf5Sequence",
    "check_fast_ycb_sequence",
    "FastYcbCheckReport",
]
