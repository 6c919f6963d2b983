// The path tracers over the width-4 kernels, compiled apart from the other widths'.
#include "renderer/frames_of_width.h"

namespace canopy {

template uint64_t render_of_width<4>(const AnyKernel&, const FrameJob&);
template uint64_t count_of_width<4>(const AnyKernel&, const FrameJob&, tbb::enumerable_thread_specific<TraversalCounts>&);
template void replay_of_width<4>(const AnyKernel&, const FrameSettings&, std::span<const RecordedRay>, std::span<Hit>);

}  // namespace canopy
