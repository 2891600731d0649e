// libFuzzer harness: every benchmark report machine-profile reads (the first byte picks the
// kind) and the SPH report the model reads.
#include "fuzz_common.hpp"
#include "sphperf/model/profile.hpp"
#include "sphperf/model/sph_run.hpp"

#include <array>
#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t *data, std::size_t size) {
    using namespace sphperf;
    if (size < 1)
        return 0;
    constexpr std::array<std::string_view, 5> kinds{"stream", "dgemm", "dgemm-alternative",
                                                    "pingpong", "exchange"};
    const std::string_view kind = kinds[data[0] % kinds.size()];
    const auto path = fuzz::scratch_file("report.json", data + 1, size - 1);
    fuzz::refuses_or_reads([&] {
        const auto j = model::load_report(path, kind == "dgemm-alternative" ? "dgemm" : kind);
        model::check_report(j, kind, path.string());
    });
    fuzz::refuses_or_reads([&] { (void)model::load_sph_run(path); });
    return 0;
}
