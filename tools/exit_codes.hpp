#pragma once
/// @file
/// One error policy for every `pvcgel` subcommand: the same mistake gives the
/// same exit code whichever subcommand made it. Listed by `pvcgel --help`.

namespace pvcgel::tools {

inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;        ///< the work failed: unreadable or unusable data, I/O, a refused fit
inline constexpr int kExitConfiguration = 2;  ///< a configuration or model file is missing, not TOML, or refused
inline constexpr int kExitNoDaemon = 3;       ///< no daemon answered, or the rig id is unknown
inline constexpr int kExitRejected = 4;       ///< the daemon refused the command or chunk
inline constexpr int kExitRecordingGap = 5;   ///< `record`: telemetry samples were lost
inline constexpr int kExitUsage = 64;         ///< the command line itself is wrong (sysexits EX_USAGE)

/// The table printed at the end of `pvcgel --help`.
inline constexpr const char* kExitCodeHelp =
    "Exit codes (every subcommand): 0 ok; 1 failure (bad data, I/O, refused fit); 2 configuration or model file "
    "error; 3 no daemon or unknown rig; 4 rejected by the daemon; 5 record lost samples; 64 usage error.";

}  // namespace pvcgel::tools
