#pragma once
// The renderer's stages that StillSceneRenderer reuses apart (internal): the light of a scene
// without targets, the scene's light with the targets traced over it, and the lens blur.
#include "robocal/vision/renderer.hpp"

#include <opencv2/core.hpp>

#include <vector>

namespace robocal::vision::detail {

// The light of a scene without targets: every pixel as render_scene gives one no target meets.
cv::Mat background_light(int W, int H, const RenderOptions& o);

// The pixels of `background` (background_light(W, H, o), given to save its computation) with
// those a target may be seen in rendered over it. `changed` (when not null): the rectangle of
// pixels that may differ from the background (occluders aside).
SceneIrradiance render_scene(const CameraRays& rays, const std::vector<RenderTarget>& targets,
                             const RenderOptions& o, bool with_subcells,
                             const cv::Mat* background = nullptr, cv::Rect* changed = nullptr);

// The lens blur acting before the pixels integrate: each uniform pixel spreads its light with
// the pixel-to-pixel kernel (Gaussian convolved with two pixel boxes, separable); an edge pixel
// spreads each of its sub-cells with that sub-cell's exact kernel. Beyond the image border the
// scene is taken as the mirror image of the scene inside (cv::BORDER_REFLECT).
// `blurred_background` (when given): this blur of the scene's pixels outside `changed`, i.e. of
// a scene that differs from it only there; the rest is taken from it. The filter's sums are the
// same for a part of an image as for the whole (OpenCV reads a part's surroundings from the
// whole), so the result is the same to the bit.
cv::Mat blur_before_sampling(const SceneIrradiance& scene, double sigma,
                             const cv::Mat* blurred_background = nullptr,
                             const cv::Rect& changed = {});

}  // namespace robocal::vision::detail
