"""Typed errors of the product. Each carries a message a technician can act on."""

from __future__ import annotations

IO_ERROR = "io_error"  # an OSError no earlier check caught, reported with its file


class OmnisortError(Exception):
    """Base of every error the product raises on purpose; `code` is stable for the protocol."""

    code = "error"
    exit_code = 2


class InputError(OmnisortError):
    """A file, image or argument given by the user is unusable (the message names it)."""

    code = "bad_input"


class ConfigError(OmnisortError):
    """A configuration or scene file is wrong; the message names the key. Exit status 78
    (sysexits' EX_CONFIG): the unit's RestartPreventExitStatus keeps systemd from restarting a
    cell whose configuration cannot work."""

    code = "bad_config"
    exit_code = 78


class NoDisplayError(OmnisortError):
    """A command that opens a window was run where there is no display (the message names
    the alternatives that need none)."""

    code = "no_display"


class CalibrationError(OmnisortError):
    """A calibration could not be computed from the data given (the message says why)."""

    code = "calibration_failed"


class FeatureNotFoundError(CalibrationError):
    """An expected image feature (board, border, marker, laser stripe) was not found."""

    code = "feature_not_found"


class NoLaserLineError(FeatureNotFoundError):
    """The image shows no laser line (`core.laser_presence`): nothing is measured on the light
    of spots, coloured marks or defocused patches."""

    code = "no_laser_line"


class CalibrationFileError(OmnisortError):
    """A calibration file is missing, corrupt, stale or from another camera."""

    code = "bad_calibration_file"


class NotRegisteredError(CalibrationFileError):
    """The system calibration has no robot base yet: cubes cannot be given in the robot's
    frame until `register_robot` ran (motion is refused separately, as motion_refused)."""

    code = "not_registered"


class StorageError(OmnisortError):
    """A file of the state or log directory could not be written (the message names the path
    and the operating system's error); nothing already stored was changed."""

    code = "storage_error"


class MotionRefusedError(OmnisortError):
    """A motion was refused before anything was sent to the arm."""

    code = "motion_refused"


class CalibrationDriftError(MotionRefusedError):
    """Motion refused: the camera turned on its mount since the calibration (the message names
    the measured angle); cleared by a recalibration or `acknowledge_drift`."""

    code = "calibration_drift"


class NotAvailableError(OmnisortError):
    """A command needs a section of the cell file, or a component, that this cell does not
    have (the message names it)."""

    code = "not_available"


class MissingExtraError(OmnisortError):
    """An optional feature was asked for without its extra installed (the message names the
    pip extra to install)."""

    code = "missing_extra"


class ExecutorTimeoutError(OmnisortError):
    """A sweep's executor saw no trial finish within its timeout (a hung worker, a cluster
    gone)."""

    code = "executor_timeout"
