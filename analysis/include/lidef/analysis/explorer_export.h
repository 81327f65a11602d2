// ParaView file of the σ3 explorer (VTK-free header; VTK is linked privately by lidef_analysis).
#pragma once
#include <string>

#include "lidef/explorer/ball_fields.h"

namespace lidef {

// Writes a BallFieldGrid as .vti (point data sigma1, sigma2, sigma3, detJ as Float32, NaN outside the ball;
// inside_ball as UInt8; sigma3 active). Atomic like vtk_export.h: on failure `path` is untouched and
// InputError(path, ...) is thrown.
void write_ball_fields_vti(const std::string& path, const BallFieldGrid& grid);

}  // namespace lidef
