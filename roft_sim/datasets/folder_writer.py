"""What the two folder formats (fast-ycb, bop) share: the writer set-up and the finish.

A folder sequence keeps its writer state in ``<sequence>/.roft_sim_parts/`` until
:meth:`~roft_sim.datasets.writer_base.StreamingWriter.finalize`, writes ``metadata.json`` inside
the folder, creates the folders of sets that happen to hold no file (a detector that always
missed), and its reader refuses a folder whose writer has not finished
(:func:`check_finished_folder`). HDF5 keeps its parts beside the file and is not a folder writer.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from roft_sim.datasets.atomic_files import atomic_write_text
from roft_sim.datasets.metadata import dumps_json
from roft_sim.datasets.writer_base import StreamingWriter, WriterSettings
from roft_sim.errors import DatasetFormatError, located
from roft_sim.records import ObjectModel

__all__ = ["PARTS_DIR_NAME", "METADATA_FILE", "FolderWriter", "check_finished_folder"]

PARTS_DIR_NAME = ".roft_sim_parts"
"""The writer's working folder inside an unfinished folder sequence."""
METADATA_FILE = "metadata.json"
"""The sequence metadata inside a folder sequence."""


def check_finished_folder(path: Path) -> None:
    """Readers' check that ``path`` is not a sequence still being written.

    Raises:
        DatasetFormatError: the folder holds the writer's parts folder.
    """
    if (path / PARTS_DIR_NAME).is_dir():
        raise DatasetFormatError(
            f"{located(path)} is an unfinished sequence (its writer did not finalize); "
            "resume the generator or call finalize() on its writer"
        )


class FolderWriter(StreamingWriter):
    """A :class:`StreamingWriter` whose sequence is the folder ``sequence_path``."""

    def __init__(
        self,
        sequence_path: Path,
        settings: WriterSettings,
        *,
        object_model: ObjectModel | None,
        resume: bool,
    ) -> None:
        super().__init__(
            sequence_path=sequence_path,
            parts_dir=sequence_path / PARTS_DIR_NAME,
            settings=settings,
            object_model=object_model,
            resume=resume,
        )

    def _metadata_path(self) -> Path:
        return self.sequence_path / METADATA_FILE

    def _finish_folder(
        self,
        metadata: dict[str, Any],
        *,
        mask_set_dir: Callable[[str], Path],
        flow_set_dir: Callable[[str], Path],
    ) -> None:
        """Creates the folder of every mask and flow set (sets that hold no file too) and
        writes ``metadata.json`` last."""
        for name in metadata["sets"]["mask"]:
            mask_set_dir(name).mkdir(parents=True, exist_ok=True)
        for name in metadata["sets"]["flow"]:
            flow_set_dir(name).mkdir(parents=True, exist_ok=True)
        atomic_write_text(self._metadata_path(), dumps_json(metadata))
