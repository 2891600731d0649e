// libFuzzer harness: a model.json as sphmodel predict reads it (load_report, then every section
// predict uses: traces, regressions, compute costs, memory order, machine links, time-sharing,
// jitter).
#include "fuzz_common.hpp"
#include "sphperf/model/profile.hpp"
#include "sphperf/model/runtime.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t *data, std::size_t size) {
    using namespace sphperf;
    const auto path = fuzz::scratch_file("model.json", data, size);
    model::PredictRequest req;
    req.setup = "dambreak";
    req.grid = "table";
    req.scale = 0.5;
    req.ranks = {1, 2};
    req.steps = 20;
    req.interval = 10;
    fuzz::refuses_or_reads([&] {
        const auto m = model::load_report(path, "sphmodel-calibration");
        (void)model::predict(nlohmann::json::object(), m, req);
    });
    return 0;
}
