#include "tools/viewer/overlay.h"

#include <cmath>

#include <imgui.h>

#include "render/color_maps.h"
#include "tools/cli_util.h"
#include "tools/render_flags.h"

namespace octocosm {
namespace {

constexpr ColorMode kColorModes[] = {ColorMode::kDensity, ColorMode::kSpeed, ColorMode::kLineOfSightVelocity,
                                     ColorMode::kVelocityDispersion, ColorMode::kType};
constexpr ColorMapId kColorMaps[] = {ColorMapId::kMagma, ColorMapId::kInferno, ColorMapId::kViridis,
                                     ColorMapId::kCoolwarm, ColorMapId::kGray};

const ImVec4 kErrorColour{1.0f, 0.45f, 0.4f, 1.0f};

unsigned long long U(std::uint64_t v) { return static_cast<unsigned long long>(v); }

bool SliderDouble(const char* label, double* value, double lo, double hi, const char* format, bool logarithmic) {
  return ImGui::SliderScalar(label, ImGuiDataType_Double, value, &lo, &hi, format,
                             logarithmic ? ImGuiSliderFlags_Logarithmic : ImGuiSliderFlags_None);
}

void ColorMapCombo(const char* label, ColorMapId& map) {
  if (!ImGui::BeginCombo(label, ColorMapName(map))) return;
  for (ColorMapId m : kColorMaps) {
    if (ImGui::Selectable(ColorMapName(m), m == map)) map = m;
  }
  ImGui::EndCombo();
}

void Statistics(const OverlayReport& r) {
  const FrameStats& f = r.frame;
  ImGui::Text("%.1f fps, %.1f ms a frame; CPU: select %.1f, upload %.1f, draw calls %.1f", r.fps, r.frame_ms,
              f.select_ms, f.upload_ms, f.draw_ms);
  if (r.gpu_times) {
    ImGui::Text("GPU (%s path): draw %.1f, measure %.1f, tone map %.1f ms", r.splat_path, r.gpu_times->draw_ms,
                r.gpu_times->measure_ms, r.gpu_times->tone_map_ms);
  }
  ImGui::Text("points drawn %llu of %llu selected%s", U(f.points_drawn), U(f.points_selected),
              f.budget_reached ? " (budget reached)" : "");
  if (r.selected > 0) {
    ImGui::Text("highlighted IDs %zu: %s", r.selected,
                f.highlight_exact ? "each particle at full detail" : "points of the level of detail (looking them up)");
  }
  ImGui::Text("nodes %llu, stand-ins %llu, epochs drawn %u", U(f.nodes_selected), U(f.stand_ins), f.epochs_drawn);
  ImGui::Text("blocks missing %llu, uploaded %llu (%s)", U(f.blocks_missing), U(f.blocks_uploaded),
              HumanBytes(static_cast<double>(f.bytes_uploaded)).c_str());
  ImGui::Text("on the GPU: %llu blocks, %s", U(f.gpu_blocks), HumanBytes(static_cast<double>(f.gpu_bytes)).c_str());
  const std::uint64_t lookups = r.cache.hits + r.cache.misses;
  ImGui::Text("block cache: %llu hits, %llu misses (%.1f%% hits), %s of %s", U(r.cache.hits), U(r.cache.misses),
              lookups ? 100.0 * static_cast<double>(r.cache.hits) / static_cast<double>(lookups) : 0.0,
              HumanBytes(static_cast<double>(r.cache.resident_bytes)).c_str(),
              HumanBytes(static_cast<double>(r.cache.capacity_bytes)).c_str());
  ImGui::Text("read from disk: %llu blocks, %s", U(r.disk.blocks), HumanBytes(static_cast<double>(r.disk.bytes)).c_str());
  ImGui::Text("exposure %.4g (mass per pixel at full brightness)", r.exposure);
  if (!r.last_error.empty()) ImGui::TextColored(kErrorColour, "last error: %s", r.last_error.c_str());
}

void TimeControls(Playback& playback) {
  if (playback.last() == 0) {
    ImGui::TextDisabled("one epoch: nothing to play");
    return;
  }
  double time = playback.time();
  if (SliderDouble("epoch", &time, 0, playback.last(), "%.2f", false)) playback.set_time(time);
  if (ImGui::Button(playback.playing() ? "pause" : "play")) playback.Toggle();
  ImGui::SameLine();
  bool loop = playback.loop();
  if (ImGui::Checkbox("loop", &loop)) playback.set_loop(loop);
  ImGui::SameLine();
  double speed = playback.speed();
  ImGui::SetNextItemWidth(140);
  if (SliderDouble("epochs/s", &speed, 0.02, 20, "%.2f", true)) playback.set_speed(speed);
}

void DetailControls(const OverlayReport& r, ViewerSettings& settings) {
  LodOptions& lod = settings.lod;
  if (r.store_links_clusters) {
    bool by_clusters = settings.cluster_error > 0;
    if (ImGui::Checkbox("cluster by cluster", &by_clusters)) settings.cluster_error = by_clusters ? kDefaultClusterError : 0;
  }
  if (settings.cluster_error > 0) {
    SliderDouble("cluster error (particle masses)", &settings.cluster_error, 0.1, 10000, "%.3g", true);
  } else {
    SliderDouble("error (pixels)", &lod.pixel_threshold, 0.25, 64, "%.2f", true);
  }
  const std::uint64_t step = 100000, step_fast = 1000000;
  ImGui::InputScalar("point budget (0: none)", ImGuiDataType_U64, &lod.point_budget, &step, &step_fast);
}

void ColourControls(const OverlayReport& r, ToneMapSettings& tone) {
  if (ImGui::BeginCombo("colour", ColorModeName(tone.color))) {
    for (ColorMode mode : kColorModes) {
      const bool usable = r.store_has_velocity || !ColorModeNeedsVelocity(mode);
      if (ImGui::Selectable(ColorModeName(mode), mode == tone.color, usable ? 0 : ImGuiSelectableFlags_Disabled)) {
        tone.color = mode;
        tone.attribute_map = DefaultAttributeColorMap(mode);
        tone.attribute_low = tone.attribute_high = 0;  // the automatic range of the new attribute
      }
    }
    ImGui::EndCombo();
  }
  ColorMapCombo("density map", tone.density_map);
  if (tone.color != ColorMode::kDensity) ColorMapCombo("attribute map", tone.attribute_map);

  int curve = tone.curve == ToneCurve::kLog ? 0 : 1;
  ImGui::RadioButton("log", &curve, 0);
  ImGui::SameLine();
  ImGui::RadioButton("asinh", &curve, 1);
  tone.curve = curve == 0 ? ToneCurve::kLog : ToneCurve::kAsinh;
  if (tone.curve == ToneCurve::kLog) {
    SliderDouble("decades", &tone.log_decades, 0.5, 12, "%.1f", false);
  } else {
    SliderDouble("softening", &tone.asinh_softening, 1e-6, 0.5, "%.2g", true);
  }

  bool automatic = tone.exposure == 0;
  if (ImGui::Checkbox("automatic exposure", &automatic)) tone.exposure = automatic ? 0 : r.exposure;
  if (automatic) {
    SliderDouble("percentile", &tone.auto_percentile, 90, 100, "%.2f", false);
  } else {
    ImGui::InputDouble("exposure", &tone.exposure, 0, 0, "%.4g");
    if (ImGui::Button("brighter")) tone.exposure /= 2;
    ImGui::SameLine();
    if (ImGui::Button("darker")) tone.exposure *= 2;
    // Typed 0, less, or not a number: back to what was shown.
    if (!(tone.exposure > 0) || !std::isfinite(tone.exposure)) tone.exposure = r.exposure;
  }
}

void SelectionControls(const OverlayReport& r, std::array<char, 1024>& id_file, OverlayRequests& requests) {
  if (!r.store_has_ids) {
    ImGui::TextDisabled("this store holds no particle IDs: nothing can be selected");
    return;
  }
  ImGui::Text("%zu particles highlighted%s", r.selected, r.selection_running ? "; working out a selection..." : "");
  if (!r.selection_message.empty()) ImGui::TextWrapped("%s", r.selection_message.c_str());
  ImGui::TextDisabled("shift + drag: select the particles under a box");
  if (ImGui::Button("clear")) requests.clear_selection = true;
  ImGui::InputText("ID file", id_file.data(), id_file.size());
  ImGui::SameLine();
  if (ImGui::Button("load") && id_file[0] != '\0') requests.id_file = std::string(id_file.data());
}

}  // namespace

OverlayRequests Overlay::Draw(const OverlayReport& r, ViewerSettings& settings, Playback& playback) {
  OverlayRequests requests;
  ImGui::SetNextWindowPos(ImVec2(10, 10), ImGuiCond_FirstUseEver);
  ImGui::SetNextWindowSize(ImVec2(560, 0), ImGuiCond_FirstUseEver);
  ImGui::SetNextWindowBgAlpha(0.75f);
  if (!ImGui::Begin("octocosm view")) {
    ImGui::End();
    return requests;
  }
  Statistics(r);
  ImGui::Text("camera: %s at (%.5g, %.5g, %.5g), flying %.3g/s", CameraModeName(r.camera_mode), r.camera_position[0],
              r.camera_position[1], r.camera_position[2], r.fly_speed);
  if (r.script_running) ImGui::TextDisabled("playing the camera path");
  if (!r.status.empty()) ImGui::TextWrapped("%s", r.status.c_str());
  if (ImGui::Button("screenshot")) requests.screenshot = true;

  if (ImGui::CollapsingHeader("time", ImGuiTreeNodeFlags_DefaultOpen)) TimeControls(playback);
  if (ImGui::CollapsingHeader("level of detail")) DetailControls(r, settings);
  if (ImGui::CollapsingHeader("colour")) ColourControls(r, settings.tone);
  if (ImGui::CollapsingHeader("selection", ImGuiTreeNodeFlags_DefaultOpen)) SelectionControls(r, id_file_, requests);
  if (ImGui::CollapsingHeader("controls")) {
    ImGui::TextUnformatted(
        "left drag: orbit (fly: look)      right/middle drag: pan\n"
        "wheel: zoom (fly: speed)          W A S D E Q: fly, shift faster\n"
        "shift + left drag: box select     F: orbit/fly\n"
        "space: play/pause                 left/right: previous/next epoch\n"
        "R: reset view   C: clear selection   H: overlay   P: screenshot\n"
        "Esc: abandon a box or a selection being worked out");
  }
  ImGui::TextDisabled("%s", r.gl_description.c_str());
  ImGui::End();
  return requests;
}

void Overlay::DrawSelectionBox(const ScreenRectangle& box, int framebuffer_height) {
  // Back to ImGui's screen coordinates: y down, in window units.
  const ImGuiIO& io = ImGui::GetIO();
  const float sx = io.DisplayFramebufferScale.x, sy = io.DisplayFramebufferScale.y;
  const ImVec2 a(static_cast<float>(box.x0) / sx, static_cast<float>(framebuffer_height - box.y1) / sy);
  const ImVec2 b(static_cast<float>(box.x1) / sx, static_cast<float>(framebuffer_height - box.y0) / sy);
  ImDrawList* draw = ImGui::GetForegroundDrawList();
  draw->AddRectFilled(a, b, IM_COL32(90, 255, 90, 40));
  draw->AddRect(a, b, IM_COL32(90, 255, 90, 220));
}

}  // namespace octocosm
