#pragma once
/// @file
/// `pvcgel ident --rig ID`: runs the excitation plan on a running pvcgeld over
/// DDS (open-loop voltage mode) and saves one recording per experiment.

#include <filesystem>
#include <string>

#include "tools/dds_client.hpp"
#include "tools/ident_command.hpp"

namespace pvcgel::tools {

/// Runs every point of the plan (and the held-out validation experiments, in
/// `dir/validation/`) on the rig and writes them as recordings into `dir`.
/// The rig is left DISABLED in displacement mode, also when this fails
/// (@throws std::runtime_error naming the experiment and the reason).
/// @return a summary line for the report.
std::string run_plan_on_rig(const IdentArgs& args, const ClientOptions& rig, const std::filesystem::path& dir);

}  // namespace pvcgel::tools
