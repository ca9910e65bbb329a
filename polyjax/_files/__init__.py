"""The one owner of what polyjax writes on the user's disk.

- :mod:`.atomic`: every output file is written through :func:`write_atomically` (a temporary file made with
  ``tempfile.mkstemp`` in the target's folder, flushed and fsynced, then renamed over the target; removed on any
  failure), after :func:`check_output_path` has checked the target before any work;
- :mod:`.trust`: whether a folder or file may be trusted to hold programs polyjax loads (owned by the current user,
  not writable by group or others), and the ownership marker of polyjax's cache folders;
- :mod:`.inside`: paths written inside input files stay inside the input's folder (:func:`inside_folder`).
"""

from .atomic import (
    check_output_path,
    remove_temporary_files,
    write_atomically,
    write_bytes_atomically,
    write_npz_atomically,
)
from .inside import inside_folder
from .trust import (
    MARKER,
    UntrustedFolderWarning,
    is_polyjax_folder,
    make_cache_folder,
    mark_cache_folder,
    trusted,
    untrusted_reason,
    warn_untrusted,
)

__all__ = ["MARKER", "UntrustedFolderWarning", "check_output_path", "inside_folder", "is_polyjax_folder",
           "make_cache_folder", "mark_cache_folder", "remove_temporary_files", "trusted", "untrusted_reason",
           "warn_untrusted", "write_atomically", "write_bytes_atomically", "write_npz_atomically"]
