// `vdyn-recorder export FILE --foxglove OUT.mcap`: a copy of a recording with Foxglove's scene
// added, so that Foxglove's 3D panel shows the cars and their forces moving as the recording
// plays: per vehicle /vehicle/<id>/tf (foxglove.FrameTransforms) and /vehicle/<id>/scene
// (foxglove.SceneUpdate: body, wheels, force arrows) at --scene-hz of log time, and the terrain on
// /vdyn/world - built as vdyn-foxglove builds them (vdyn/foxglove/scene.h), stamped with the
// recording's log time. Every record of the recording is copied as it is (the original channels
// unchanged); the copy is written beside OUT and renamed when whole, never over the recording.
#pragma once

#include <filesystem>
#include <ostream>

namespace vdyn::recorder {

struct FoxgloveExportOptions {
  std::filesystem::path file;
  std::filesystem::path out;
  double scene_hz = 60;
  double arrow_m_per_kn = 0.5;
};
// 0 done, 1 some states did not parse (skipped, said); a bad file throws mcap::McapError.
int RunExportFoxglove(const FoxgloveExportOptions& o, std::ostream& out);

}  // namespace vdyn::recorder
